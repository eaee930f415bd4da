//! Which technique renders a generator's caustics, and why. A game that leaves the
//! choice to the plugin (`Auto`) gets the technique this table picks from what the
//! generator is; one that names a technique gets it where it can run, and otherwise
//! `Auto`'s pick with the reason it was passed over. Nothing is ever silently dark.
//!
//! The table, by what each technique models (docs/choosing-a-technique.md has the
//! measured errors behind it):
//! - a **closed refractor** (a watertight glass or water body) bends light twice or
//!   more, in and out: hierarchical maps follow every face their traced paths cross
//!   (past Wyman 2008 §3.1's image-space pair), warped volumes one (Ernst et al. 2005
//!   §3.1), which focuses in the wrong place;
//! - an **open refracting surface** (water, an ocean, a pool) bends light once, where
//!   the volumes are exact per triangle and resolution-free over any extent, and they
//!   alone draw the shafts in a participating medium (§3.5);
//! - a **mirror** reflects once, which both model, and both keep the light off the
//!   receivers the generator itself shadows (the maps' receiver map, the volumes' hit
//!   planes); read at 8² points a cell the two tie on the ring (docs/choosing-a-technique.md), so the
//!   mirror stays with the volumes, the default the table started from, which also
//!   draw its beams in a participating medium — except beside a closed refractor,
//!   where it joins the glass on the maps, whose traced paths carry light between the
//!   two (`GeneratorFacts::with_closed_refractor`).

use crate::mesh::TriMesh;
use crate::params::SpecularInteraction;
use crate::scene::Sides;
use std::fmt;

/// The four published techniques.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Technique {
    /// Ernst, Akenine-Möller & Jensen 2005: a caustic volume per generator triangle.
    WarpedVolumes,
    /// Iwasaki et al.: illumination textures on virtual planes around a receiver.
    IlluminationTextures,
    /// Trendall & Stewart 2000: pool-floor irradiance as convolutions of a heightfield.
    Convolution,
    /// Wyman 2008: hierarchical caustic maps from a photon buffer per light.
    HierarchicalMaps,
}

impl Technique {
    /// Every technique.
    pub const ALL: [Technique; 4] = [Technique::WarpedVolumes, Technique::IlluminationTextures, Technique::Convolution, Technique::HierarchicalMaps];

    /// The technique's name in prose.
    pub fn label(self) -> &'static str {
        match self {
            Technique::WarpedVolumes => "warped volumes",
            Technique::IlluminationTextures => "illumination textures",
            Technique::Convolution => "convolution",
            Technique::HierarchicalMaps => "hierarchical maps",
        }
    }
}

impl fmt::Display for Technique {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.label())
    }
}

/// What a generator is, as far as the choice of technique goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GeneratorShape {
    /// A watertight refracting mesh ([`crate::mesh::TriMesh::is_closed`]): light enters
    /// and leaves it.
    ClosedRefractor,
    /// A refracting surface with a boundary: light crosses it once.
    OpenRefractor,
    /// A rippling pool's water (a heightfield of known depth over a flat floor): the
    /// only shape convolution caustics apply to.
    Pool,
    /// A mirror, open or closed.
    Mirror,
}

impl GeneratorShape {
    /// The shape of a generator mesh that is neither a pool nor an ocean (those are
    /// open surfaces by construction, known to the caller): a mirror, or a refractor
    /// closed or open by [`TriMesh::is_closed`].
    pub fn of(mesh: &TriMesh, interaction: &SpecularInteraction) -> Self {
        match interaction {
            SpecularInteraction::Reflect => GeneratorShape::Mirror,
            SpecularInteraction::Refract { .. } if mesh.is_closed() => GeneratorShape::ClosedRefractor,
            SpecularInteraction::Refract { .. } => GeneratorShape::OpenRefractor,
        }
    }

    /// Whether the caustic maps' traced paths follow light onto a generator of this
    /// shape that another technique draws (`hierarchical::PhotonPaths::Traced`):
    /// mirrors and closed refractors. Open water is left out: an ocean or a pool
    /// changes its mesh every frame, which would rebuild the maps' BVH and maps every
    /// frame; light through it from a glass body goes on unbent.
    pub fn traced_through(self) -> bool {
        matches!(self, GeneratorShape::Mirror | GeneratorShape::ClosedRefractor)
    }

    /// The shape in prose.
    pub fn label(self) -> &'static str {
        match self {
            GeneratorShape::ClosedRefractor => "closed refractor",
            GeneratorShape::OpenRefractor => "open refracting surface",
            GeneratorShape::Pool => "rippling pool",
            GeneratorShape::Mirror => "mirror",
        }
    }
}

/// What the choice reads of a generator and its scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct GeneratorFacts {
    /// What the generator is.
    pub shape: GeneratorShape,
    /// Whether a participating medium overlaps the generator's bounds: part of the
    /// reason given (only the volumes draw its shafts), no bearing on the choice since
    /// every generator the volumes can draw already prefers them.
    pub in_medium: bool,
    /// Which sides of its faces take part (glTF's `doubleSided`); no bearing on the
    /// choice, kept for the techniques.
    pub sides: Sides,
    /// Whether the scene holds a closed refractor (which the maps draw): a mirror then
    /// joins it there, outside a medium, so that the maps' traced paths follow the
    /// light both ways between them — glass onto the mirror, the mirror into the glass.
    /// Apart, each technique would draw only the light that meets its generator first
    /// (docs/hierarchical-maps.md: `mirror_bunny` 0.14 L2 on the maps, 0.23 split between the two).
    pub with_closed_refractor: bool,
}

impl GeneratorFacts {
    /// A mirror that joins a closed refractor on the maps: beside one, outside a medium
    /// (where only the volumes draw its beams).
    fn mirror_beside_glass(&self) -> bool {
        self.shape == GeneratorShape::Mirror && self.with_closed_refractor && !self.in_medium
    }

    /// `Auto`'s order of preference, best first; later ones stand in where an earlier
    /// one is unavailable. Every technique that applies to the shape is listed.
    pub fn preferences(&self) -> &'static [Technique] {
        use Technique::*;
        match self.shape {
            GeneratorShape::ClosedRefractor => &[HierarchicalMaps, IlluminationTextures, WarpedVolumes],
            GeneratorShape::Mirror if self.mirror_beside_glass() => &[HierarchicalMaps, WarpedVolumes],
            GeneratorShape::OpenRefractor | GeneratorShape::Mirror => &[WarpedVolumes, HierarchicalMaps],
            GeneratorShape::Pool => &[WarpedVolumes, HierarchicalMaps, Convolution],
        }
    }
}

/// Why a technique was passed over.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Unavailable {
    /// Its cargo feature is off in this build.
    NotCompiled,
    /// It does not model this kind of generator (convolution needs a pool).
    NotApplicable,
}

impl Unavailable {
    fn label(self) -> &'static str {
        match self {
            Unavailable::NotCompiled => "not in this build (cargo feature off)",
            Unavailable::NotApplicable => "does not apply to this generator",
        }
    }
}

/// Whether `technique` can draw a generator of `shape`, given whether its code is
/// compiled in.
pub fn availability(technique: Technique, shape: GeneratorShape, compiled: bool) -> Result<(), Unavailable> {
    let applies = match technique {
        Technique::Convolution => shape == GeneratorShape::Pool,
        // A light transport table needs a closed mesh for its far side (§3).
        Technique::IlluminationTextures => shape == GeneratorShape::ClosedRefractor,
        Technique::WarpedVolumes | Technique::HierarchicalMaps => true,
    };
    if !compiled {
        Err(Unavailable::NotCompiled)
    } else if !applies {
        Err(Unavailable::NotApplicable)
    } else {
        Ok(())
    }
}

/// The technique a generator gets, with the reason.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct TechniqueChoice {
    /// The technique chosen.
    pub technique: Technique,
    /// The generator named this technique itself.
    pub requested: bool,
    /// What the choice read of the generator and its scene.
    pub facts: GeneratorFacts,
    /// Techniques tried first and why each could not be used: the requested one, then
    /// `Auto`'s preferences in order.
    pub passed_over: Vec<(Technique, Unavailable)>,
}

impl fmt::Display for TechniqueChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (technique, why) in &self.passed_over {
            write!(f, "{technique}: {}; ", why.label())?;
        }
        if self.requested {
            write!(f, "{} as set on the generator", self.technique)
        } else {
            let medium = if self.facts.in_medium { " in a participating medium" } else { "" };
            let glass = if self.facts.mirror_beside_glass() { " beside a closed refractor" } else { "" };
            write!(f, "{}{medium}{glass} → {}", self.facts.shape.label(), self.technique)
        }
    }
}

/// Picks the technique for a generator: `requested` (`None` for `Auto`) where it can
/// run, else the first of `Auto`'s preferences that can. `compiled` says whether a
/// technique's code is in this build. `None` when nothing that is compiled in can draw
/// the generator.
pub fn choose(requested: Option<Technique>, facts: GeneratorFacts, compiled: impl Fn(Technique) -> bool) -> Option<TechniqueChoice> {
    let mut passed_over = Vec::new();
    let candidates = requested.into_iter().map(|t| (t, true)).chain(facts.preferences().iter().map(|&t| (t, false)));
    for (technique, is_requested) in candidates {
        if passed_over.iter().any(|&(t, _)| t == technique) {
            continue;
        }
        match availability(technique, facts.shape, compiled(technique)) {
            Ok(()) => return Some(TechniqueChoice { technique, requested: is_requested, facts, passed_over }),
            Err(why) => passed_over.push((technique, why)),
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL_SHAPES: [GeneratorShape; 4] = [GeneratorShape::ClosedRefractor, GeneratorShape::OpenRefractor, GeneratorShape::Pool, GeneratorShape::Mirror];

    fn facts(shape: GeneratorShape) -> GeneratorFacts {
        GeneratorFacts { shape, in_medium: false, sides: Sides::Front, with_closed_refractor: false }
    }

    #[test]
    fn auto_follows_the_table_and_says_why() {
        let all = |_| true;
        let pick = |shape, in_medium| choose(None, GeneratorFacts { in_medium, ..facts(shape) }, all).unwrap();
        assert_eq!(pick(GeneratorShape::ClosedRefractor, false).technique, Technique::HierarchicalMaps);
        assert_eq!(pick(GeneratorShape::OpenRefractor, false).technique, Technique::WarpedVolumes);
        assert_eq!(pick(GeneratorShape::Pool, false).technique, Technique::WarpedVolumes);
        assert_eq!(pick(GeneratorShape::Mirror, false).technique, Technique::WarpedVolumes);
        assert_eq!(pick(GeneratorShape::Mirror, true).technique, Technique::WarpedVolumes);
        assert_eq!(pick(GeneratorShape::ClosedRefractor, false).to_string(), "closed refractor → hierarchical maps");
        assert_eq!(pick(GeneratorShape::Mirror, true).to_string(), "mirror in a participating medium → warped volumes");
        // Beside a closed refractor, a mirror joins it on the maps, but for the shafts.
        let beside = |in_medium| choose(None, GeneratorFacts { in_medium, with_closed_refractor: true, ..facts(GeneratorShape::Mirror) }, all).unwrap();
        assert_eq!(beside(false).to_string(), "mirror beside a closed refractor → hierarchical maps");
        assert_eq!(beside(true).technique, Technique::WarpedVolumes);
    }

    #[test]
    fn a_requested_technique_that_cannot_run_falls_back_to_auto_and_says_so() {
        // Every technique, requested with its feature off, on every shape: the result is
        // Auto's pick among the rest, and the reason names the requested one first.
        for requested in Technique::ALL {
            for shape in ALL_SHAPES {
                let compiled = |t: Technique| t != requested;
                let choice = choose(Some(requested), facts(shape), compiled).expect("another technique applies");
                assert_ne!(choice.technique, requested);
                assert!(!choice.requested);
                assert_eq!(choice.passed_over[0].0, requested);
                let auto = choose(None, facts(shape), compiled).unwrap();
                assert_eq!(choice.technique, auto.technique, "{requested:?} on {shape:?}");
                assert!(choice.to_string().starts_with(requested.label()), "{choice}");
            }
        }
        let textures = choose(Some(Technique::IlluminationTextures), facts(GeneratorShape::OpenRefractor), |_| true).unwrap();
        assert_eq!(textures.to_string(), "illumination textures: does not apply to this generator; open refracting surface → warped volumes");
        let convolution = choose(Some(Technique::Convolution), facts(GeneratorShape::OpenRefractor), |_| true).unwrap();
        assert_eq!(convolution.passed_over, vec![(Technique::Convolution, Unavailable::NotApplicable)]);
        assert_eq!(convolution.technique, Technique::WarpedVolumes);
    }

    #[test]
    fn requested_techniques_that_can_run_are_kept() {
        for (requested, shape) in [
            (Technique::WarpedVolumes, GeneratorShape::ClosedRefractor),
            (Technique::HierarchicalMaps, GeneratorShape::OpenRefractor),
            (Technique::Convolution, GeneratorShape::Pool),
            (Technique::IlluminationTextures, GeneratorShape::ClosedRefractor),
        ] {
            let choice = choose(Some(requested), facts(shape), |_| true).unwrap();
            assert_eq!((choice.technique, choice.requested), (requested, true));
            assert!(choice.passed_over.is_empty());
        }
    }

    #[test]
    fn a_build_without_any_applicable_technique_chooses_nothing() {
        let only_convolution = |t| t == Technique::Convolution;
        assert_eq!(choose(None, facts(GeneratorShape::Mirror), only_convolution), None);
        assert_eq!(choose(None, facts(GeneratorShape::Pool), only_convolution).unwrap().technique, Technique::Convolution);
    }
}
