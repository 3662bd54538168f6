//! Scalars the exact response can be evaluated in: `f64`, or forward-mode dual numbers that
//! carry exact partial derivatives alongside (for the Jacobians of the identification).

use std::ops::{Add, Div, Mul, Neg, Sub};

/// A real scalar: `f64` or a [`Dual`].
pub trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// A constant (zero derivatives).
    fn cst(x: f64) -> Self;
    /// The value, without derivatives.
    fn value(self) -> f64;
    /// `eˣ`.
    fn exp(self) -> Self;
    /// `eˣ − 1`, accurate near 0.
    fn exp_m1(self) -> Self;
    /// `ln(1 + x)`, accurate near 0.
    fn ln_1p(self) -> Self;
    /// `√x`.
    fn sqrt(self) -> Self;
    /// `sin x`.
    fn sin(self) -> Self;
    /// `cos x`.
    fn cos(self) -> Self;
    /// `sinh x`.
    fn sinh(self) -> Self;
    /// `cosh x`.
    fn cosh(self) -> Self;
}

/// The methods of [`Real`] named, each calling `f64`'s own method of that name.
macro_rules! forward_to_f64 {
    ($($name:ident),*) => {
        $(
            #[inline(always)]
            fn $name(self) -> Self {
                f64::$name(self)
            }
        )*
    };
}

impl Real for f64 {
    #[inline(always)]
    fn cst(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn value(self) -> f64 {
        self
    }
    forward_to_f64!(exp, exp_m1, ln_1p, sqrt, sin, cos, sinh, cosh);
}

/// A value with its partial derivatives with respect to `N` inputs (forward-mode automatic
/// differentiation): `f(x + ε) = f(x) + f'(x) ε` with `ε² = 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dual<const N: usize> {
    /// The value.
    pub v: f64,
    /// `∂v/∂xᵢ`.
    pub d: [f64; N],
}

impl<const N: usize> Default for Dual<N> {
    /// Zero with zero derivatives.
    fn default() -> Self {
        Dual {
            v: 0.0,
            d: [0.0; N],
        }
    }
}

impl<const N: usize> Dual<N> {
    /// The `i`-th input variable with value `v` (derivative 1 with respect to itself).
    pub fn variable(v: f64, i: usize) -> Self {
        let mut d = [0.0; N];
        if let Some(slot) = d.get_mut(i) {
            *slot = 1.0;
        }
        Dual { v, d }
    }

    #[inline(always)]
    fn chain(self, v: f64, dv: f64) -> Self {
        Dual {
            v,
            d: self.d.map(|x| x * dv),
        }
    }
}

impl<const N: usize> Add for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        let mut d = self.d;
        for (a, b) in d.iter_mut().zip(o.d) {
            *a += b;
        }
        Dual { v: self.v + o.v, d }
    }
}

impl<const N: usize> Sub for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        let mut d = self.d;
        for (a, b) in d.iter_mut().zip(o.d) {
            *a -= b;
        }
        Dual { v: self.v - o.v, d }
    }
}

impl<const N: usize> Mul for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        let mut d = self.d;
        for (a, b) in d.iter_mut().zip(o.d) {
            *a = *a * o.v + self.v * b;
        }
        Dual { v: self.v * o.v, d }
    }
}

impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        let inv = 1.0 / o.v;
        let v = self.v * inv;
        let mut d = self.d;
        for (a, b) in d.iter_mut().zip(o.d) {
            *a = (*a - v * b) * inv;
        }
        Dual { v, d }
    }
}

impl<const N: usize> Neg for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Dual {
            v: -self.v,
            d: self.d.map(|x| -x),
        }
    }
}

impl<const N: usize> Real for Dual<N> {
    #[inline(always)]
    fn cst(x: f64) -> Self {
        Dual { v: x, d: [0.0; N] }
    }
    #[inline(always)]
    fn value(self) -> f64 {
        self.v
    }
    #[inline(always)]
    fn exp(self) -> Self {
        let e = self.v.exp();
        self.chain(e, e)
    }
    #[inline(always)]
    fn exp_m1(self) -> Self {
        self.chain(self.v.exp_m1(), self.v.exp())
    }
    #[inline(always)]
    fn ln_1p(self) -> Self {
        self.chain(self.v.ln_1p(), 1.0 / (1.0 + self.v))
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        self.chain(s, 0.5 / s)
    }
    #[inline(always)]
    fn sin(self) -> Self {
        self.chain(self.v.sin(), self.v.cos())
    }
    #[inline(always)]
    fn cos(self) -> Self {
        self.chain(self.v.cos(), -self.v.sin())
    }
    #[inline(always)]
    fn sinh(self) -> Self {
        self.chain(self.v.sinh(), self.v.cosh())
    }
    #[inline(always)]
    fn cosh(self) -> Self {
        self.chain(self.v.cosh(), self.v.sinh())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derivatives_of_elementary_functions_match_finite_differences() {
        type Case = (&'static str, fn(Dual<1>) -> Dual<1>, fn(f64) -> f64);
        let fs: [Case; 8] = [
            ("exp", |x| x.exp(), f64::exp),
            ("exp_m1", |x| x.exp_m1(), f64::exp_m1),
            ("ln_1p", |x| x.ln_1p(), f64::ln_1p),
            ("sqrt", |x| x.sqrt(), f64::sqrt),
            ("sin", |x| x.sin(), f64::sin),
            ("cos", |x| x.cos(), f64::cos),
            ("sinh", |x| x.sinh(), f64::sinh),
            ("cosh", |x| x.cosh(), f64::cosh),
        ];
        for (name, fd, f) in fs {
            for x in [0.3, 1.7, 2.9] {
                let h = 1e-6;
                let numeric = (f(x + h) - f(x - h)) / (2.0 * h);
                let exact = fd(Dual::variable(x, 0)).d[0];
                assert!(
                    (numeric - exact).abs() < 1e-8 * (1.0 + exact.abs()),
                    "{name}({x})"
                );
            }
        }
        let x = Dual::<2>::variable(3.0, 0);
        let y = Dual::<2>::variable(2.0, 1);
        let q = (x * y - x / y + -x) / (x + y);
        // q = (xy − x/y − x)/(x + y); by hand at (3, 2): ∂q/∂x = 1/25, ∂q/∂y = 17.25/25.
        assert!((q.v - 0.3).abs() < 1e-15);
        assert!((q.d[0] - 0.04).abs() < 1e-12 && (q.d[1] - 0.69).abs() < 1e-12);
    }
}
