//! Just enough x87 extended precision (64-bit mantissa "long double") to
//! reproduce LinuxCNC's results to the last bit.
//!
//! LinuxCNC converts degrees to radians with `M_PIl`, a long double, so
//! `SIN[x]` is `sinl((x * M_PIl) / 180)` and `ATAN[y]/[x]` is
//! `(atan2(y, x) * 180) / M_PIl`, each operation rounded to 64 mantissa
//! bits, and the arc centre of an R-format arc uses `atan2(…) ± M_PI_2l`.
//! With plain doubles the result can differ in its last bit, which shows
//! when a value that is zero in exact arithmetic (`SIN[180]`) comes out
//! with the other sign, or a coordinate sits on a rounding tie. This
//! module does those few operations exactly as the hardware rounds them,
//! with integer arithmetic.

/// A finite extended-precision number: `(-1)^neg * mant * 2^exp`, with
/// `mant` normalised (top bit set) or zero.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Ld {
    neg: bool,
    mant: u64,
    exp: i32,
}

/// π rounded to 64 bits, as `M_PIl`.
const PI_L: Ld = Ld {
    neg: false,
    mant: 0xC90F_DAA2_2168_C235,
    exp: -62,
};

/// π/2 rounded to 64 bits, as `M_PI_2l`.
const PI_2_L: Ld = Ld {
    neg: false,
    mant: 0xC90F_DAA2_2168_C235,
    exp: -63,
};

/// Round the magnitude `m * 2^exp` (with `sticky` set when bits below `m`
/// were non-zero) to `bits` significant bits, half to even.
fn round_to(neg: bool, m: u128, exp: i32, sticky: bool, bits: u32) -> Ld {
    if m == 0 {
        return Ld {
            neg,
            mant: 0,
            exp: 0,
        };
    }
    let len = 128 - m.leading_zeros();
    let (mut m, mut exp) = if len > bits {
        let drop = len - bits;
        let kept = m >> drop;
        let rest = m & ((1u128 << drop) - 1);
        let half = 1u128 << (drop - 1);
        let up = rest > half || (rest == half && (sticky || kept & 1 == 1));
        (kept + up as u128, exp + drop as i32)
    } else {
        (m << (bits - len), exp - (bits - len) as i32)
    };
    if m >> bits != 0 {
        // Rounding carried into a new top bit.
        m >>= 1;
        exp += 1;
    }
    // Keep 64-bit mantissas left-aligned so that every Ld looks alike.
    let shift = 64 - bits;
    Ld {
        neg,
        mant: (m as u64) << shift,
        exp: exp - shift as i32,
    }
}

impl Ld {
    fn from_f64(v: f64) -> Ld {
        if v == 0.0 || !v.is_finite() {
            return Ld {
                neg: v.is_sign_negative(),
                mant: 0,
                exp: 0,
            };
        }
        let bits = v.to_bits();
        let neg = bits >> 63 != 0;
        let e = ((bits >> 52) & 0x7ff) as i32;
        let frac = bits & ((1u64 << 52) - 1);
        let (m, exp) = if e == 0 {
            (frac, -1074)
        } else {
            (frac | (1u64 << 52), e - 1075)
        };
        round_to(neg, m as u128, exp, false, 64)
    }

    fn mul(self, o: Ld) -> Ld {
        let m = self.mant as u128 * o.mant as u128;
        round_to(self.neg != o.neg, m, self.exp + o.exp, false, 64)
    }

    fn div(self, o: Ld) -> Ld {
        if self.mant == 0 || o.mant == 0 {
            return Ld {
                neg: self.neg != o.neg,
                mant: 0,
                exp: 0,
            };
        }
        // Long division to at least 66 quotient bits, so that rounding
        // to 64 sees a guard bit as well as the sticky remainder.
        let d = o.mant as u128;
        let num = (self.mant as u128) << 64;
        let (q1, r1) = (num / d, num % d);
        let q = (q1 << 8) | ((r1 << 8) / d);
        let sticky = (r1 << 8) % d != 0;
        round_to(self.neg != o.neg, q, self.exp - 72 - o.exp, sticky, 64)
    }

    fn add(self, o: Ld) -> Ld {
        if self.mant == 0 {
            return o;
        }
        if o.mant == 0 {
            return self;
        }
        // Align on the smaller exponent; a term more than 64 bits below
        // the other only matters as a sticky bit.
        let (hi, lo) = if self.exp >= o.exp {
            (self, o)
        } else {
            (o, self)
        };
        let d = (hi.exp - lo.exp) as u32;
        let (a, b, exp, sticky) = if d <= 62 {
            ((hi.mant as i128) << d, lo.mant as i128, lo.exp, false)
        } else {
            // Keep 2 guard bits below hi and fold the rest into sticky.
            ((hi.mant as i128) << 2, 0, hi.exp - 2, true)
        };
        let a = if hi.neg { -a } else { a };
        let b = if lo.neg { -b } else { b };
        let s = a + b;
        round_to(s < 0, s.unsigned_abs(), exp, sticky, 64)
    }

    /// Round to the nearest double (half to even).
    fn to_f64(self) -> f64 {
        if self.mant == 0 {
            return if self.neg { -0.0 } else { 0.0 };
        }
        let r = round_to(self.neg, self.mant as u128, self.exp, false, 53);
        let v = (r.mant >> 11) as f64 * 2f64.powi(r.exp + 11);
        if self.neg {
            -v
        } else {
            v
        }
    }

    /// `(hi, lo)` with `hi` the nearest double and `hi + lo` exactly `self`.
    fn split(self) -> (f64, f64) {
        let hi = self.to_f64();
        let lo = self.add(Ld::from_f64(-hi)).to_f64();
        (hi, lo)
    }
}

/// `x * M_PIl / 180` as LinuxCNC computes it, split into two doubles.
fn radians(degrees: f64) -> (f64, f64) {
    Ld::from_f64(degrees)
        .mul(PI_L)
        .div(Ld::from_f64(180.0))
        .split()
}

// ---- double-double arithmetic, for sine and cosine of a long double ----
//
// A value is an unevaluated sum hi + lo of two doubles (about 106 bits),
// enough to round sinl's result to the same double.

type Dd = (f64, f64);

fn two_sum(a: f64, b: f64) -> Dd {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

fn dd_add(a: Dd, b: Dd) -> Dd {
    let (s, e) = two_sum(a.0, b.0);
    let e = e + a.1 + b.1;
    two_sum(s, e)
}

fn dd_mul(a: Dd, b: Dd) -> Dd {
    let p = a.0 * b.0;
    let e = a.0.mul_add(b.0, -p) + (a.0 * b.1 + a.1 * b.0);
    two_sum(p, e)
}

/// π/2 as three doubles (their sum is π/2 to about 160 bits).
const HALF_PI_3: [f64; 3] = [
    std::f64::consts::FRAC_PI_2,
    6.123_233_995_736_766e-17,
    -1.497_384_904_859_169_8e-33,
];

/// sin and cos of a double-double `x` with |x| ≤ π/4, by Taylor series.
fn dd_sin_cos_small(x: Dd) -> (Dd, Dd) {
    let x2 = dd_mul(x, x);
    // sin: x - x³/3! + …; cos: 1 - x²/2! + …, summed from the smallest
    // term up; 14 terms reach far below 2^-106 for |x| ≤ π/4.
    let mut sin = (0.0, 0.0);
    let mut cos = (0.0, 0.0);
    for k in (0..14).rev() {
        let n = 2 * k as u32;
        // 1/(2k+1)! and 1/(2k)! as double-doubles from exact integers.
        let fs = recip_factorials()[n as usize + 1];
        let fc = recip_factorials()[n as usize];
        let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
        sin = dd_add(dd_mul(sin, x2), (sign * fs.0, sign * fs.1));
        cos = dd_add(dd_mul(cos, x2), (sign * fc.0, sign * fc.1));
    }
    (dd_mul(sin, x), cos)
}

/// 1/0! … 1/28! as double-doubles, computed once.
fn recip_factorials() -> &'static [Dd; 29] {
    static TABLE: std::sync::OnceLock<[Dd; 29]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|n| dd_recip_factorial(n as u32)))
}

/// 1/n! as a double-double.
fn dd_recip_factorial(n: u32) -> Dd {
    let mut f: Dd = (1.0, 0.0);
    for i in 2..=n {
        f = dd_mul(f, (i as f64, 0.0));
    }
    // One Newton step on the double reciprocal: r + r(1 - f r).
    let r = 1.0 / f.0;
    let fr = dd_mul(f, (r, 0.0));
    let err = dd_add((1.0, 0.0), (-fr.0, -fr.1));
    dd_add((r, 0.0), dd_mul((r, 0.0), err))
}

/// sin and cos of the double-double `x` (any size that G-code uses).
fn dd_sin_cos(x: Dd) -> (Dd, Dd) {
    let k = (x.0 / HALF_PI_3[0]).round();
    // r = x - k·π/2, with π/2 in three parts so that the cancellation near
    // a multiple of π/2 keeps its precision.
    let mut r = x;
    for part in HALF_PI_3 {
        r = dd_add(r, dd_mul((-k, 0.0), (part, 0.0)));
    }
    let (s, c) = dd_sin_cos_small(r);
    let neg = neg_dd;
    match (k as i64).rem_euclid(4) {
        0 => (s, c),
        1 => (c, neg(s)),
        2 => (neg(s), neg(c)),
        _ => (neg(c), s),
    }
}

/// LinuxCNC's `SIN[x]` (x in degrees).
pub(crate) fn sin_deg(x: f64) -> f64 {
    let s = dd_sin_cos(radians(x)).0;
    s.0 + s.1
}

/// LinuxCNC's `COS[x]` (x in degrees).
pub(crate) fn cos_deg(x: f64) -> f64 {
    let c = dd_sin_cos(radians(x)).1;
    c.0 + c.1
}

/// LinuxCNC's `TAN[x]` (x in degrees).
pub(crate) fn tan_deg(x: f64) -> f64 {
    let (s, c) = dd_sin_cos(radians(x));
    // s / c to double-double precision: a quotient, then its correction.
    let q = s.0 / c.0;
    let rest = dd_add(s, neg_dd(dd_mul((q, 0.0), c)));
    q + rest.0 / c.0
}

fn neg_dd(v: Dd) -> Dd {
    (-v.0, -v.1)
}

/// Radians to degrees as LinuxCNC does for ATAN, ASIN and ACOS:
/// `(r * 180.0) / M_PIl`, where `r * 180.0` is a product of doubles
/// (rounded to a double) and only the division is in long double.
pub(crate) fn degrees(radians: f64) -> f64 {
    Ld::from_f64(radians * 180.0).div(PI_L).to_f64()
}

/// `angle + M_PI_2l` (or minus, with `minus`), rounded to a double.
pub(crate) fn add_half_pi(angle: f64, minus: bool) -> f64 {
    let q = Ld {
        neg: minus,
        ..PI_2_L
    };
    Ld::from_f64(angle).add(q).to_f64()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constants_are_pi_rounded_to_64_bits() {
        // π = 3.14159265358979323846…; the 64-bit value is a hair above.
        let (hi, lo) = PI_L.split();
        assert_eq!(hi, std::f64::consts::PI);
        assert!(lo > 1.2246e-16 && lo < 1.2252e-16, "{lo:e}");
    }

    #[test]
    fn exact_values_stay_exact() {
        assert_eq!(Ld::from_f64(1.5).to_f64(), 1.5);
        assert_eq!(Ld::from_f64(-0.1).to_f64(), -0.1);
        assert_eq!(Ld::from_f64(3.0).mul(Ld::from_f64(7.0)).to_f64(), 21.0);
        assert_eq!(Ld::from_f64(1.0).div(Ld::from_f64(4.0)).to_f64(), 0.25);
        assert_eq!(Ld::from_f64(2.5).add(Ld::from_f64(-0.5)).to_f64(), 2.0);
        assert_eq!(sin_deg(30.0), 0.5);
        assert_eq!(cos_deg(60.0), 0.5);
        assert_eq!(degrees(std::f64::consts::FRAC_PI_4), 45.0);
    }

    /// Values LinuxCNC's rs274 printed for `X[f[a] * 1e20]` (4 decimals):
    /// the residues at the zeros come from rounding π to 64 bits, and
    /// doubles get them wrong (sin(-180°) is negative in double).
    #[test]
    fn residues_at_zeros_match_rs274() {
        type Case = (fn(f64) -> f64, f64, f64);
        let cases: [Case; 6] = [
            (sin_deg, -180.0, 5.0166),
            (sin_deg, 180.0, -5.0166),
            (cos_deg, 90.0, -2.5083),
            (cos_deg, 270.0, 18.3669),
            (sin_deg, 360.0, 10.0331),
            (tan_deg, 180.0, 5.0166),
        ];
        for (f, a, printed) in cases {
            let v = f(a) * 1e20;
            assert!((v - printed).abs() < 0.00005, "{a}: {v}");
        }
        assert!((-180f64).to_radians().sin() < 0.0);
        // Exact results stay exact, as in rs274.
        assert_eq!(degrees(0.5f64.acos()), 60.0);
        assert_eq!(degrees(0.5f64.asin()), 30.0);
    }
}
