//! A tiny counter-based random number generator: every photon gets its own stream
//! from `(seed, light, index)`, so results do not depend on thread scheduling.

/// PCG-XSH-RR 32-bit generator (O'Neill 2014) seeded by a SplitMix64 hash.
#[derive(Clone, Copy, Debug)]
pub struct Pcg32 {
    state: u64,
}

const MUL: u64 = 6364136223846793005;
const INC: u64 = 1442695040888963407;

fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E3779B97F4A7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
    z ^ (z >> 31)
}

impl Pcg32 {
    /// The stream for one photon.
    pub fn for_photon(seed: u64, light: u32, index: u64) -> Self {
        let s = splitmix64(seed ^ splitmix64(index ^ ((light as u64) << 56)));
        let mut rng = Self { state: s };
        rng.next_u32();
        rng
    }

    /// The next 32 random bits.
    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(MUL).wrapping_add(INC);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        xorshifted.rotate_right((old >> 59) as u32)
    }

    /// Uniform in [0, 1).
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }
}
