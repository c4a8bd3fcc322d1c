//! Seeded pseudo-random noise for the simulator: the same seed gives the
//! same run, on every machine. xorshift64* for uniform numbers, the polar
//! Box–Muller method for normal ones. No allocation.

/// A seeded source of uniform and normally distributed numbers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Noise {
    state: u64,
    /// The second normal number of the last Box–Muller pair.
    spare: Option<f64>,
}

impl Noise {
    /// A generator seeded with `seed` (any value; 0 is mapped to a fixed
    /// non-zero state, since xorshift stays at 0 forever).
    pub fn new(seed: u64) -> Noise {
        // Spread the seed so nearby seeds give unrelated streams (splitmix64).
        let mut z = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        Noise {
            state: if z == 0 { 0x2545_F491_4F6C_DD1D } else { z },
            spare: None,
        }
    }

    fn next_u64(&mut self) -> u64 {
        let mut x = self.state;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.state = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in [0, 1), 53 bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Standard normal (mean 0, standard deviation 1).
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        loop {
            let u = 2.0 * self.uniform() - 1.0;
            let v = 2.0 * self.uniform() - 1.0;
            let s = u * u + v * v;
            if s > 0.0 && s < 1.0 {
                let f = (-2.0 * s.ln() / s).sqrt();
                self.spare = Some(v * f);
                return u * f;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_stream_and_sane_moments() {
        let (mut a, mut b) = (Noise::new(7), Noise::new(7));
        let mut c = Noise::new(8);
        let n = 100_000;
        let (mut sum, mut sq, mut differ) = (0.0, 0.0, 0);
        for _ in 0..n {
            let x = a.normal();
            assert_eq!(x, b.normal());
            differ += (x != c.normal()) as usize;
            sum += x;
            sq += x * x;
        }
        assert!(differ > n - 10, "seeds 7 and 8 gave the same numbers");
        // Mean within 5 standard errors (5/sqrt(n) = 0.016), variance within 2 %.
        assert!((sum / n as f64).abs() < 0.016, "mean {}", sum / n as f64);
        assert!(
            (sq / n as f64 - 1.0).abs() < 0.02,
            "variance {}",
            sq / n as f64
        );
        let u = Noise::new(0).uniform();
        assert!((0.0..1.0).contains(&u));
    }
}
