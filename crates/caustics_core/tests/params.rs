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
    let medium = MediumCoefficients { scattering: -0.1, absorption: 0.0, asymmetry: 0.0 };
    let err = medium.validate().unwrap_err();
    assert!(err.to_string().contains("scattering"), "{err}");
    assert!(MediumCoefficients { scattering: 0.1, absorption: f32::NAN, asymmetry: 0.0 }.validate().is_err());
    assert!(MediumCoefficients { scattering: 0.1, absorption: 0.1, asymmetry: 1.0 }.validate().is_err());
}

#[test]
fn malformed_meshes_are_refused() {
    let p = vec![Vec3::ZERO, Vec3::X, Vec3::Z];
    let n = vec![Vec3::Y; 3];
    assert!(TriMesh::new(p.clone(), n.clone(), vec![[0, 1, 2]]).is_ok());
    assert_eq!(TriMesh::new(p.clone(), n.clone(), vec![]), Err(MeshError::Empty));
    assert!(matches!(
        TriMesh::new(p.clone(), n.clone(), vec![[0, 1, 3]]),
        Err(MeshError::IndexOutOfRange { index: 3, .. })
    ));
    assert_eq!(
        TriMesh::new(p.clone(), vec![Vec3::Y, Vec3::NAN, Vec3::Y], vec![[0, 1, 2]]),
        Err(MeshError::BadNormal(1))
    );
    assert_eq!(TriMesh::new(p.clone(), vec![Vec3::ZERO; 3], vec![[0, 1, 2]]), Err(MeshError::BadNormal(0)));
    assert_eq!(
        TriMesh::new(vec![Vec3::ZERO, Vec3::NAN, Vec3::Z], n.clone(), vec![[0, 1, 2]]),
        Err(MeshError::NonFinitePosition(1))
    );
    assert!(matches!(TriMesh::new(p, vec![Vec3::Y], vec![[0, 1, 2]]), Err(MeshError::NormalCount { .. })));
}

#[test]
fn materials_are_tagged_by_the_gltf_convention() {
    use caustics_core::scene::{SurfaceRole, role_from_material};
    assert_eq!(
        role_from_material(1.0, 1.333, 0.0, 0.0),
        Ok(SurfaceRole::Generator(SpecularInteraction::Refract { ior: 1.333, dispersion: None }))
    );
    assert_eq!(role_from_material(0.0, 1.5, 1.0, 0.0), Ok(SurfaceRole::Generator(SpecularInteraction::Reflect)));
    assert_eq!(role_from_material(0.0, 1.5, 1.0, 0.4), Ok(SurfaceRole::Receiver), "rough metal is diffuse enough");
    assert_eq!(role_from_material(0.0, 1.5, 0.0, 0.9), Ok(SurfaceRole::Receiver));
    assert!(role_from_material(1.0, 0.7, 0.0, 0.0).is_err(), "transmissive with IOR < 1");
}
