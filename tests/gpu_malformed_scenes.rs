//! The malformed corpus (`tests/malformed/`) the way a game meets it: every glTF and
//! GLB file loaded by Bevy's asset server as a scene under [`TagCausticsFromMaterials`],
//! lit by a sun and seen by a caustics camera on lavapipe. Each file's load ends — it
//! loads or fails, never hangs — within a bounded number of frames; frames keep coming
//! back with every pixel of the caustic irradiance buffer finite, whatever the meshes
//! hold (NaN or infinite positions and normals, zero scales, absurd counts: their
//! generators are skipped with a warning); the controls load and are tagged; and the
//! app agrees with the CLI: what it renders casts caustics, a generator mesh it refuses
//! casts none. The CLI's run of the same corpus is `crates/caustics_cli/tests/malformed.rs`.
//!
//! Two files give Bevy a mesh without positions, which Bevy's own prepass and shadow
//! pipelines cannot draw (wgpu's validation fails and Bevy quits, with or without this
//! plugin): for those the camera looks away, and the sun casts no Bevy shadow maps at all
//! (the plugin's caustic light has its own shadows).
//!
//! One test function: a process holds one Bevy app with a render device at a time.

mod support;

use bevy::asset::LoadState;
use bevy::gltf::GltfAssetLabel;
use bevy::prelude::*;
use bevy::world_serialization::{WorldAsset, WorldAssetRoot};
use bevy_caustics::headless::HeadlessRenderer;
use bevy_caustics::{CausticGenerator, CausticReceiver, TagCausticsFromMaterials};
use std::path::PathBuf;
use support::{render, render_caustics};

const SIZE: u32 = 32;
/// Frames a file may take to load or fail.
const MOST_FRAMES: usize = 600;

/// How a file's load ended in the app.
#[derive(Debug)]
enum Ended {
    Loaded { generators: usize, receivers: usize },
    Failed(String),
}

/// The CLI's outcome for `file` (`renders` or `fails`) and its message, from
/// `expected.tsv`.
fn cli_outcome<'a>(expected: &'a str, file: &str) -> (&'a str, &'a str) {
    let line = expected.lines().find(|l| l.split('\t').next() == Some(file)).unwrap_or_else(|| panic!("{file} is not in expected.tsv"));
    let mut fields = line.split('\t').skip(1);
    (fields.next().unwrap_or_default(), fields.next().unwrap_or_default())
}

#[test]
fn malformed_files_load_or_fail_cleanly_in_an_app() {
    let corpus = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/malformed");
    let mut files: Vec<String> = std::fs::read_dir(&corpus)
        .expect("the corpus folder")
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|name| name.ends_with(".gltf") || name.ends_with(".glb"))
        .collect();
    files.sort();
    assert!(files.len() >= 30, "the corpus has {} glTF and GLB files", files.len());

    let expected = std::fs::read_to_string(corpus.join("expected.tsv")).expect("the corpus's expected outcomes");
    let mut renderer = HeadlessRenderer::with_asset_root(SIZE, SIZE, &corpus).unwrap_or_else(|e| panic!("{e}"));
    let target = renderer.render_target();
    let camera = renderer.world_mut().spawn((support::top_down_camera(target, 4.0, SIZE, Vec3::ZERO), Msaa::Off)).id();
    renderer.world_mut().spawn((DirectionalLight { illuminance: 10_000.0, ..default() }, Transform::default().looking_to(Vec3::new(0.2, -1.0, 0.1), Vec3::X)));

    let mut outcomes = Vec::new();
    for file in &files {
        let world = renderer.world_mut();
        let handle: Handle<WorldAsset> = world.resource::<AssetServer>().load(GltfAssetLabel::Scene(0).from_asset(file.clone()));
        let root = world.spawn((WorldAssetRoot(handle.clone()), TagCausticsFromMaterials)).id();
        let mut ended = None;
        for _ in 0..MOST_FRAMES {
            renderer.app.update();
            let world = renderer.world_mut();
            match world.resource::<AssetServer>().load_state(&handle) {
                LoadState::Failed(err) => ended = Some(Ended::Failed(err.to_string().lines().next().unwrap_or_default().to_owned())),
                LoadState::Loaded if world.resource::<AssetServer>().is_loaded_with_dependencies(&handle) => {
                    // Bevy's own prepass cannot draw a mesh without positions (its
                    // pipeline fails wgpu's validation and Bevy quits): the camera looks
                    // away from such a file, and the plugin's systems still meet it.
                    let drawable = world.resource::<Assets<WorldAsset>>().get(&handle).is_some_and(|scene| {
                        let meshes = world.resource::<Assets<Mesh>>();
                        // A scene without meshes has no `Mesh3d` to query.
                        scene.world.try_query::<&Mesh3d>().is_none_or(|mut scene_meshes| {
                            scene_meshes.iter(&scene.world).all(|m| meshes.get(&m.0).is_none_or(|m| m.attribute(Mesh::ATTRIBUTE_POSITION).is_some()))
                        })
                    });
                    world.get_mut::<Camera>(camera).expect("the camera").is_active = drawable;
                    // The scene spawns and is tagged over the next frames.
                    render(&mut renderer, 3);
                    let world = renderer.world_mut();
                    let count = |world: &mut World, filter: fn(EntityRef) -> bool| world.iter_entities().filter(|e| filter(*e)).count();
                    ended = Some(Ended::Loaded {
                        generators: count(world, |e| e.contains::<CausticGenerator>()),
                        receivers: count(world, |e| e.contains::<CausticReceiver>()),
                    });
                }
                _ => {}
            }
            if ended.is_some() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        let ended = ended.unwrap_or_else(|| panic!("{file}: neither loaded nor failed after {MOST_FRAMES} frames"));
        let control = file.starts_with("control_valid");
        if control {
            render_caustics(&mut renderer, 1);
        } else {
            render(&mut renderer, 2);
        }
        let irradiance = renderer.caustic_irradiance(camera).unwrap_or_else(|e| panic!("{file}: {e}"));
        let bad = irradiance.iter().find(|e| !e.is_finite() || e.min_element() < 0.0);
        assert!(bad.is_none(), "{file} ({ended:?}): a caustic pixel holds {bad:?}");
        let lit = irradiance.iter().any(|e| e.max_element() > 0.0);
        eprintln!("{file}: {ended:?}{}", if lit { ", caustics drawn" } else { "" });
        if control {
            assert!(matches!(ended, Ended::Loaded { generators: 1.., receivers: 1.., .. }), "{file}: the control is not tagged: {ended:?}");
        }
        // The app agrees with the CLI: a file it renders casts caustics here too, and a
        // generator mesh it refuses (`glass.glass: …`) is skipped here.
        match cli_outcome(&expected, file) {
            ("renders", _) => assert!(lit, "{file}: the CLI renders it, and it casts no caustics here"),
            ("fails", why) if why.starts_with("glass.glass:") && matches!(ended, Ended::Loaded { .. }) => {
                assert!(!lit, "{file}: the CLI refuses its generator ({why}), and it casts caustics here")
            }
            _ => {}
        }
        outcomes.push(ended);
        let world = renderer.world_mut();
        world.entity_mut(root).despawn();
        world.get_mut::<Camera>(camera).expect("the camera").is_active = true;
    }
    let failed: Vec<&str> = outcomes.iter().filter_map(|o| if let Ended::Failed(why) = o { Some(why.as_str()) } else { None }).collect();
    eprintln!(
        "{} files: {} loaded, {} failed to load, each with one line:\n  {}",
        outcomes.len(),
        outcomes.len() - failed.len(),
        failed.len(),
        failed.join("\n  ")
    );
}
