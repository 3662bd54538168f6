//! Exact derivatives of the step response (dual numbers) against central finite differences.

use motor_model::{Dual, MotorParams, MotorState, StepResponse};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    /// ∂(I, Ω, θ)/∂(R, L, k, f, J, Ts) on a grid after breakaway. Tolerance: 1e-5 of the
    /// channel's scale (central differences with h = 1e-6 relative are good to ~1e-9; the
    /// scale is the largest |derivative × parameter| so that every column is compared alike).
    #[test]
    fn dual_derivatives_match_finite_differences(
        r in 0.1f64..10.0, tau_e in 1e-3f64..1.0, k in 0.01f64..1.0,
        tau_m_over_e in 0.05f64..100.0, j in 1e-4f64..1.0, rho in 0.05f64..0.9,
        e in 1.0f64..50.0,
    ) {
        let l = r * tau_e;
        let f = j / (tau_e * tau_m_over_e);
        let ts = rho * k * e / r;
        let motor = MotorParams::new(r, l, k, f, j, ts).unwrap();
        let base = motor.values();
        let duals: [Dual<6>; 6] = std::array::from_fn(|i| Dual::variable(base[i], i));
        let exact = StepResponse::from_values(duals, e);
        let t0 = exact.breakaway_time().unwrap().v;
        let horizon = 3.0 * (tau_e + tau_e * tau_m_over_e);
        let n = 200;
        let dt = horizon / n as f64;
        let mut grid = vec![MotorState::<Dual<6>>::default(); n];
        // From before breakaway (Eq. (10) samples) to ~3 slow time constants.
        let t_first = 0.3 * t0;
        exact.fill(t_first, dt, &mut grid);
        for (col, &pv) in base.iter().enumerate() {
            let h = 1e-6 * pv;
            let mut up = base;
            let mut down = base;
            up[col] += h;
            down[col] -= h;
            let (su, sd) = (StepResponse::<f64>::from_values(up, e), StepResponse::<f64>::from_values(down, e));
            let mut gu = vec![MotorState::<f64>::default(); n];
            let mut gd = vec![MotorState::<f64>::default(); n];
            // Same absolute times: the perturbed t0 moves, the samples do not.
            su.fill(t_first, dt, &mut gu);
            sd.fill(t_first, dt, &mut gd);
            type Channel = (fn(&MotorState<Dual<6>>) -> Dual<6>, fn(&MotorState<f64>) -> f64);
            let channels: [Channel; 3] = [
                (|s| s.current_a, |s| s.current_a),
                (|s| s.speed_rad_s, |s| s.speed_rad_s),
                (|s| s.position_rad, |s| s.position_rad),
            ];
            for (ch, (get_d, get_f)) in channels.iter().enumerate() {
                let scale = grid.iter().map(|s| get_d(s).d.iter().zip(base).map(|(d, p)| (d * p).abs()).fold(0.0, f64::max)).fold(0.0, f64::max);
                for i in 0..n {
                    let fd = (get_f(&gu[i]) - get_f(&gd[i])) / (2.0 * h);
                    let ad = get_d(&grid[i]).d[col];
                    prop_assert!((fd - ad).abs() * pv <= 1e-5 * scale + 1e-300,
                        "channel {ch}, parameter {col}, sample {i}: AD {ad} vs FD {fd} (scale {scale})");
                }
            }
        }
    }
}
