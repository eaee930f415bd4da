//! The built-in meshes wind every triangle counter-clockwise seen from the side its
//! vertex normals face. Bevy culls back faces by winding but shades with the vertex
//! normals: a mesh whose winding disagrees with its normals shows its far side, lit
//! as if it faced the other way.

use caustics_core::mesh::{MeshError, TriMesh};
use glam::Vec3;

/// Every triangle's geometric normal (by winding) points the way of its vertex normals.
fn assert_wound_like_normals(name: &str, mesh: &TriMesh) {
    for (t, tri) in mesh.triangles().iter().enumerate() {
        let [a, b, c] = mesh.corners(t);
        let geometric = (b - a).cross(c - a);
        if geometric.length_squared() < 1e-12 {
            continue; // a pole's degenerate triangle has no winding
        }
        for &i in tri {
            let n = mesh.normals()[i as usize];
            assert!(geometric.dot(n) > 0.0, "{name}: triangle {t} is wound against vertex {i}'s normal {n}");
        }
    }
}

#[test]
fn built_in_meshes_are_wound_like_their_normals() {
    let wavy = |x: f32, z: f32| 0.1 * (3.0 * x).sin() * (2.0 * z).cos();
    let slope = |x: f32, z: f32| Vec3::new(-0.3 * (3.0 * x).cos() * (2.0 * z).cos(), 1.0, 0.2 * (3.0 * x).sin() * (2.0 * z).sin());
    assert_wound_like_normals("heightfield", &TriMesh::heightfield(9, 2.0, wavy, slope).unwrap());
    assert_wound_like_normals("quad", &TriMesh::quad(Vec3::ONE, Vec3::X, Vec3::Z));
    assert_wound_like_normals("uv_sphere", &TriMesh::uv_sphere(Vec3::ZERO, 0.5, 6, 12));
    assert_wound_like_normals("cuboid", &TriMesh::cuboid(Vec3::new(-1.0, 0.0, -0.5), Vec3::new(0.5, 2.0, 1.5)));
    for segments in [3, 8, 64] {
        assert_wound_like_normals("ring", &TriMesh::ring(Vec3::ZERO, 1.0, 0.3, segments));
        assert_wound_like_normals("solid_ring", &TriMesh::solid_ring(Vec3::Y, 1.0, 1.05, 0.3, segments));
    }
}

#[test]
fn the_solid_ring_is_closed_with_walls_facing_in_and_out() {
    let ring = TriMesh::solid_ring(Vec3::ZERO, 1.0, 1.05, 0.3, 16);
    // Closed: every edge is shared by exactly two triangles, once in each direction,
    // counting vertices by position (the walls, top and bottom have their own).
    assert!(ring.is_closed());
    // Walls: normals horizontal, to the axis on the inner radius and away on the outer;
    // smooth around (a vertex normal is the exact radial direction).
    for (p, n) in ring.positions().iter().zip(ring.normals()) {
        let radial = Vec3::new(p.x, 0.0, p.z);
        let r = radial.length();
        if n.y.abs() < 1e-6 {
            let expected = if r < 1.025 { -radial / r } else { radial / r };
            assert!(n.distance(expected) < 1e-5, "wall normal {n} at {p}");
        }
    }
}

#[test]
fn obj_text_reads_into_a_mesh_and_bad_lines_are_named() {
    let square = "# a unit square\nv 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nvn 0 1 0\nf 1//1 4//1 3//1 2//1\n";
    let mesh = TriMesh::from_obj(square).unwrap();
    assert_eq!((mesh.positions().len(), mesh.triangles().len()), (4, 2));
    assert!(mesh.normals().iter().all(|n| (*n - Vec3::Y).length() < 1e-6), "wound counter-clockwise seen from +y");
    assert_eq!(TriMesh::from_obj("v 0 0 0\nv 1 0 0\nv 0 0 1\nf -3 -1 -2\n").unwrap().triangles(), &[[0, 2, 1]]);
    for (bad, line) in [("v 0 0\n", 1), ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", 4), ("v 0 0 0\nf 1 x 2\n", 2), ("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", 0)] {
        match TriMesh::from_obj(bad) {
            Err(MeshError::Obj { line: l, .. }) => assert_eq!(l, line, "{bad:?}"),
            Err(other) => assert_eq!(line, 0, "{bad:?}: {other}"),
            Ok(_) => panic!("{bad:?} parsed"),
        }
    }
}

#[test]
fn the_bunny_asset_is_closed_and_wound_outwards() {
    let bunny = TriMesh::from_obj(include_str!("../../../assets/models/bunny.obj")).unwrap();
    assert_eq!((bunny.positions().len(), bunny.triangles().len()), (1839, 3674));
    // Every edge once each way: closed, consistently wound; positive volume: outwards.
    assert!(bunny.is_closed());
    let volume: f32 = (0..bunny.triangles().len())
        .map(|t| {
            let [a, b, c] = bunny.corners(t);
            a.dot(b.cross(c)) / 6.0
        })
        .sum();
    assert!(volume > 0.0);
}

#[test]
fn closedness_welds_split_vertices_and_sees_holes_and_flips() {
    let sphere = TriMesh::uv_sphere(Vec3::ZERO, 0.5, 16, 32);
    let cube = TriMesh::cuboid(Vec3::ZERO, Vec3::ONE);
    // Both split their corners: the sphere at its seam and poles, the cube per face.
    assert!(sphere.is_closed(), "a UV sphere (seam and poles welded)");
    assert!(cube.is_closed(), "a cube with a vertex set per face");
    assert!(TriMesh::solid_ring(Vec3::ZERO, 1.0, 1.05, 0.3, 64).is_closed());
    assert!(!TriMesh::ring(Vec3::ZERO, 1.0, 0.3, 64).is_closed(), "an open cylinder wall");
    assert!(!TriMesh::quad(Vec3::ZERO, Vec3::X, Vec3::Z).is_closed(), "a plane");
    let rebuilt = |positions: Vec<Vec3>, triangles: Vec<[u32; 3]>| TriMesh::new(positions, cube.normals().to_vec(), triangles).unwrap();
    // A face missing: open.
    let tris = cube.triangles();
    assert!(!rebuilt(cube.positions().to_vec(), tris[..tris.len() - 2].to_vec()).is_closed());
    // A face wound the wrong way: edges meet in the same direction.
    let mut flipped = tris.to_vec();
    flipped[0].swap(1, 2);
    flipped[1].swap(1, 2);
    assert!(!rebuilt(cube.positions().to_vec(), flipped).is_closed());
    // Corners off by 10⁻⁶ (rounding in an exporter) still weld; a 1 cm gap does not.
    let jitter = |d: f32| cube.positions().iter().enumerate().map(|(i, p)| *p + Vec3::splat(d * (i % 3) as f32)).collect::<Vec<_>>();
    assert!(rebuilt(jitter(1e-6), tris.to_vec()).is_closed());
    assert!(!rebuilt(jitter(1e-2), tris.to_vec()).is_closed());
}
