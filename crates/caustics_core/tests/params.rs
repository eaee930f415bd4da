//! Bad parameters are errors with a message, never panics.

use caustics_core::mesh::{MeshError, TriMesh};
use caustics_core::optics::CauchyDispersion;
use caustics_core::params::*;
use glam::Vec3;

#[test]
fn impossible_parameters_are_refused_with_a_reason() {
    assert!(matches!(check_ior(0.5), Err(ParamError::ImpossibleIor(_))));
    assert!(check_ior(f32::NAN).is_err());
    assert!(check_ior(f32::INFINITY).is_err());
    assert_eq!(check_ior(1.0), Ok(1.0));
    let bad = SpecularInteraction::Refract { ior: 1.5, dispersion: Some(CauchyDispersion { a: 0.9, b: 0.001 }) };
    assert!(bad.validate().is_err());
    let medium = MediumCoefficients { scattering: -0.1, absorption: Vec3::splat(0.0), asymmetry: 0.0 };
    let err = medium.validate().unwrap_err();
    assert!(err.to_string().contains("scattering"), "{err}");
    let err = MediumCoefficients { scattering: 0.1, absorption: Vec3::new(0.1, f32::NAN, 0.1), asymmetry: 0.0 }.validate().unwrap_err();
    assert!(err.to_string().contains("absorption (green)"), "{err}");
    assert!(MediumCoefficients { scattering: 0.1, absorption: Vec3::splat(0.1), asymmetry: 1.0 }.validate().is_err());
}

#[test]
fn a_scene_file_gives_absorption_per_channel_or_as_one_number() {
    let parse = |json: &str| serde_json::from_str::<MediumCoefficients>(json);
    let rgb = parse(r#"{"scattering": 0.2, "absorption": [0.3, 0.05, 0.01], "asymmetry": 0.5}"#).unwrap();
    assert_eq!(rgb.absorption, Vec3::new(0.3, 0.05, 0.01));
    assert!(rgb.extinction().abs_diff_eq(Vec3::new(0.5, 0.25, 0.21), 1e-6), "{}", rgb.extinction());
    let grey = parse(r#"{"scattering": 0.2, "absorption": 0.05, "asymmetry": 0.5}"#).unwrap();
    assert_eq!(grey.absorption, Vec3::splat(0.05));
    assert_eq!(parse(&serde_json::to_string(&rgb).unwrap()).unwrap(), rgb);
    assert!(parse(r#"{"scattering": 0.2, "absorption": [0.3, 0.05], "asymmetry": 0.5}"#).is_err());
}

#[test]
fn malformed_meshes_are_refused() {
    let p = vec![Vec3::ZERO, Vec3::X, Vec3::Z];
    let n = vec![Vec3::Y; 3];
    assert!(TriMesh::new(p.clone(), n.clone(), vec![[0, 1, 2]]).is_ok());
    assert_eq!(TriMesh::new(p.clone(), n.clone(), vec![]), Err(MeshError::Empty));
    assert!(matches!(TriMesh::new(p.clone(), n.clone(), vec![[0, 1, 3]]), Err(MeshError::IndexOutOfRange { index: 3, .. })));
    assert_eq!(TriMesh::new(p.clone(), vec![Vec3::Y, Vec3::NAN, Vec3::Y], vec![[0, 1, 2]]), Err(MeshError::BadNormal(1)));
    assert_eq!(TriMesh::new(p.clone(), vec![Vec3::ZERO; 3], vec![[0, 1, 2]]), Err(MeshError::BadNormal(0)));
    assert_eq!(TriMesh::new(vec![Vec3::ZERO, Vec3::NAN, Vec3::Z], n.clone(), vec![[0, 1, 2]]), Err(MeshError::NonFinitePosition(1)));
    assert!(matches!(TriMesh::new(p.clone(), vec![Vec3::Y], vec![[0, 1, 2]]), Err(MeshError::NormalCount { .. })));
    // Found by the fuzzer: finite coordinates whose products overflow made the BVH
    // builder panic and the tracer emit infinite flux. Refused past MAX_COORDINATE;
    // at it, the mesh is kept.
    let scaled = |s: f32| p.iter().map(|&v| v * s).collect::<Vec<_>>();
    assert!(TriMesh::new(scaled(caustics_core::mesh::MAX_COORDINATE), n.clone(), vec![[0, 1, 2]]).is_ok());
    for huge in [1e20, 3e38] {
        let refused = TriMesh::new(scaled(huge), n.clone(), vec![[0, 1, 2]]);
        assert!(matches!(refused, Err(MeshError::PositionTooLarge { index: 1, .. })), "{refused:?}");
        assert!(refused.unwrap_err().to_string().contains("1e12"));
    }
}

#[test]
fn lights_too_strong_for_f32_are_refused() {
    use caustics_core::scene::{Light, LightKind, MAX_LIGHT_POWER};
    let point = |intensity: f32, color: Vec3| Light { color, ..Light::white(LightKind::Point { position: Vec3::Y, intensity }) };
    assert!(point(MAX_LIGHT_POWER, Vec3::ONE).validate().is_ok());
    // Found by the fuzzer: 3.4e38 cd a kilometre away gave the volumes NaN irradiance.
    assert!(point(f32::MAX, Vec3::ONE).validate().is_err());
    assert!(point(1e19, Vec3::splat(100.0)).validate().is_err(), "the colour counts");
    assert!(point(1.0, Vec3::new(1.0, -1.0, 1.0)).validate().is_err(), "a negative colour");
    let sun = Light::white(LightKind::Directional { direction: Vec3::NEG_Y, irradiance: 1e21 });
    assert!(sun.validate().unwrap_err().to_string().contains("1e20"));
}

#[test]
fn materials_are_tagged_by_the_gltf_convention() {
    use caustics_core::scene::{SurfaceRole, role_from_material};
    assert_eq!(role_from_material(1.0, 1.333, 0.0, 0.0), Ok(SurfaceRole::Generator(SpecularInteraction::Refract { ior: 1.333, dispersion: None })));
    assert_eq!(role_from_material(0.0, 1.5, 1.0, 0.0), Ok(SurfaceRole::Generator(SpecularInteraction::Reflect)));
    assert_eq!(role_from_material(0.0, 1.5, 1.0, 0.4), Ok(SurfaceRole::Receiver), "rough metal is diffuse enough");
    assert_eq!(role_from_material(0.0, 1.5, 0.0, 0.9), Ok(SurfaceRole::Receiver));
    assert!(role_from_material(1.0, 0.7, 0.0, 0.0).is_err(), "transmissive with IOR < 1");
}
