use morphlink::tune::{convection_for_tau_w_m2k, fit::Method};
#[test]
fn probe() {
    for m in [Method::Asymptotic, Method::LeastSquares] {
        for tau in [20.0f32, 25.0, 30.0, 42.07, 60.0] { for n in [54usize, 90] {
            println!("{m:?} {tau} {n} {:?}", convection_for_tau_w_m2k(tau, m, n)); }
        }
    }
}
