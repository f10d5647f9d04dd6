//! Reproducible damage to files, for the mutation tests and fuzz seeds of every crate: a small
//! deterministic generator and one mutation step (truncate, append garbage, overwrite a
//! field-sized run with an extreme value, flip bits).

/// xorshift64*: reproducible test randomness without a dependency.
#[derive(Clone, Debug)]
pub struct Rng(pub u64);

impl Rng {
    /// The next number. (Not an `Iterator`: the stream never ends and callers want a `u64`.)
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in `0..n` (0 when `n` is 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// One random mutation of `good`, and what it did (for failure messages).
pub fn mutate(rng: &mut Rng, good: &[u8]) -> (Vec<u8>, String) {
    let mut b = good.to_vec();
    let what = match rng.below(5) {
        0 => {
            let n = rng.below(good.len() + 1);
            b.truncate(n);
            format!("truncated to {n} bytes")
        }
        1 => {
            let n = rng.below(200) + 1;
            b.extend((0..n).map(|_| rng.next() as u8));
            format!("{n} bytes of garbage appended")
        }
        2 => {
            let at = rng.below(b.len());
            let v: [u8; 8] = match rng.below(3) {
                0 => [0xFF; 8],
                1 => [0; 8],
                _ => rng.next().to_le_bytes(),
            };
            let n = 1 + rng.below(8);
            for (i, x) in v.iter().take(n).enumerate() {
                if let Some(y) = b.get_mut(at + i) {
                    *y = *x;
                }
            }
            format!("{n} bytes at {at} set to {:02x?}", &v[..n])
        }
        _ => {
            let mut at = Vec::new();
            for _ in 0..1 + rng.below(8) {
                let i = rng.below(b.len());
                let bit = rng.below(8);
                if let Some(y) = b.get_mut(i) {
                    *y ^= 1 << bit;
                }
                at.push((i, bit));
            }
            format!("bits flipped (byte, bit): {at:?}")
        }
    };
    (b, what)
}
