//! Reproducible random draws for the ensembles of simulated links (the lumped mismatch ensemble
//! in `morphlink-sim`, the high-fidelity links in `morphlink-plant`): one generator, so draw `i`
//! of seed `s` means the same thing everywhere and can be replayed alone.

/// SplitMix64: a small, well-mixed generator; advances `state` and returns the next value.
pub fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A value uniform in `[lo, hi)` from the next draw of `state`.
pub fn uniform(state: &mut u64, (lo, hi): (f64, f64)) -> f64 {
    let u = (splitmix(state) >> 11) as f64 / (1u64 << 53) as f64;
    lo + (hi - lo) * u
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_are_reproducible_and_in_range() {
        let (mut a, mut b) = (7u64, 7u64);
        for _ in 0..1000 {
            let x = uniform(&mut a, (2.0, 3.0));
            assert_eq!(x, uniform(&mut b, (2.0, 3.0)));
            assert!((2.0..3.0).contains(&x));
        }
        assert_ne!(splitmix(&mut 1), splitmix(&mut 2));
    }
}
