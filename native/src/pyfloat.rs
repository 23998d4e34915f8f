//! Floats as the Python side writes them: `repr(x)` / `str(x)` (summaries), orjson (JSONL),
//! `round(x, n)` and `f"{x:.nf}"`.
//!
//! Rust's `{:e}` gives the shortest round-trip digits, as Python's repr and orjson do; only the
//! layout differs. Rust's fixed-precision formatting rounds the exact binary value half to
//! even, as Python's `%` formatting and `round()` do.

use crate::json::push_u64;
use std::fmt::Write;

/// The shortest round-trip digits of a finite non-zero |x| and its decimal exponent:
/// 1234.5 -> ("12345", 3).
fn shortest(x: f64) -> (String, i32) {
    let a = x.abs();
    let (mut digits, mut exp) = split_e(&format!("{a:e}"));
    if digits.len() >= 16 && tie_possible(a) {
        // When |x| lies exactly halfway between the two nearest shortest candidates, Rust takes
        // the upper one and Python's repr (David Gay's dtoa) and orjson the even one
        // (926001165992679.25 -> ...679.2). Rust's fixed-precision formatting rounds the exact
        // value half to even: taken when it reads back as x. (A tie needs 16+ digits.)
        let (mut even, even_exp) = split_e(&format!("{:.*e}", digits.len() - 1, a));
        even.truncate(even.trim_end_matches('0').len().max(1));
        let back = format!("{}e{}", even, even_exp - even.len() as i32 + 1);
        if even != digits && back.parse() == Ok(a) {
            digits = even;
            exp = even_exp;
        }
    }
    (digits, exp)
}

/// Whether the exact value of |x| could lie halfway between two 16- or 17-digit decimals: only
/// if its exact decimal expansion is short (at most 18 significant digits, ending in 5). The
/// exact value is m / 2^k = m * 5^k / 10^k (m odd): k fractional digits, m * 5^k significant.
fn tie_possible(a: f64) -> bool {
    let bits = a.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i32;
    let mut m = bits & ((1 << 52) - 1);
    let mut e2 = if biased == 0 {
        -1074
    } else {
        m |= 1 << 52;
        biased - 1075
    };
    if m == 0 {
        return false;
    }
    let tz = m.trailing_zeros();
    m >>= tz;
    e2 += tz as i32;
    if e2 >= 0 {
        return false; // an integer: ends in 5 only when odd, and then below 2^53 (16 digits)
    }
    let k = e2.unsigned_abs();
    k <= 25 && u128::from(m) * 5u128.pow(k) < 1_000_000_000_000_000_000
}

/// "1.2345e3" -> ("12345", 3)
fn split_e(s: &str) -> (String, i32) {
    let (mant, exp) = s.split_once('e').expect("{:e} has an exponent");
    let digits: String = mant.chars().filter(|c| *c != '.').collect();
    (digits, exp.parse().expect("{:e} exponent is an integer"))
}

/// Lay out digits/exponent: positional when `lo <= exp < 16`, else scientific.
fn layout(out: &mut String, x: f64, lo: i32, pad_exp: bool) {
    if x == 0.0 {
        out.push_str(if x.is_sign_negative() { "-0.0" } else { "0.0" });
        return;
    }
    if x.is_sign_negative() {
        out.push('-');
    }
    let (digits, exp) = shortest(x);
    if exp >= lo && exp < 16 {
        if exp < 0 {
            out.push_str("0.");
            for _ in 0..(-exp - 1) {
                out.push('0');
            }
            out.push_str(&digits);
        } else {
            let int_len = exp as usize + 1;
            if digits.len() <= int_len {
                out.push_str(&digits);
                for _ in digits.len()..int_len {
                    out.push('0');
                }
                out.push_str(".0");
            } else {
                out.push_str(&digits[..int_len]);
                out.push('.');
                out.push_str(&digits[int_len..]);
            }
        }
    } else {
        out.push_str(&digits[..1]);
        if digits.len() > 1 {
            out.push('.');
            out.push_str(&digits[1..]);
        }
        out.push('e');
        out.push(if exp < 0 { '-' } else { '+' });
        if pad_exp {
            let _ = write!(out, "{:02}", exp.abs());
        } else {
            let _ = write!(out, "{}", exp.abs());
        }
    }
}

/// The common case, without allocating: Rust's `Display` writes the same shortest round-trip
/// digits positionally; only a whole number lacks Python's ".0". (Within these ranges the
/// shortest digits' exponent is the one `layout` would test: a double below 1e16 never has
/// "1e16" as its shortest digits, since those read back as another double.)
fn push_positional(out: &mut String, x: f64, lo: i32) {
    if push_short_decimal(out, x) {
        return;
    }
    push_positional_fmt(out, x, lo);
}

/// 10^d, exact in a double.
const POW10: [f64; 7] = [1.0, 10.0, 100.0, 1e3, 1e4, 1e5, 1e6];

/// The fast path of `push_positional` for the floats the decoders mostly make (26.46 mm,
/// 0.12 ms, 70.0, candump times 1763700000.119925): x is the double nearest to n·10^-d for an
/// integer n (exact in a double) and d <= 6, and n·10^-d is then the only decimal of d or fewer
/// decimals that reads back as x, so it is the shortest round-trip text and there is no tie to
/// break. Unique when either
/// - n has at most 15 digits: two decimals of at most 15 significant digits never round to the
///   same double (DBL_DIG = 15); or
/// - ulp(x) < 10^-d: the decimals reading back as x lie in an interval at most ulp(x) wide, too
///   narrow for two multiples of 10^-d (and a shorter decimal is a multiple of 10^-d too).
///
/// `n / 10^d == x` checks "nearest" exactly (both operands exact, the division correctly
/// rounded), whatever rounding `x * 10^d` had.
fn push_short_decimal(out: &mut String, x: f64) -> bool {
    let a = x.abs();
    // the gap to the next double up (a power of two: the products below are exact)
    let ulp = f64::from_bits(a.to_bits() + 1) - a;
    // Most floats here have 6 decimals or fewer (candump times, latencies): try 6 first. When
    // n·10^-6 is unique (the conditions above) and reads back as x, the decimal of the fewest
    // decimals that reads back as x is n·10^-6 without its trailing zeros (it is one of the
    // 6-decimal decimals too, and there is only one): what the loop below would find, in one
    // step instead of up to seven.
    let p6 = POW10[6];
    let n = round_cheap(x * p6);
    if !(n.abs() >= 1e15 && (n.abs() >= 9_007_199_254_740_992.0 || ulp * p6 >= 1.0)) && n / p6 == x
    {
        push_decimal(out, x < 0.0, n.abs() as u64, 6);
        return true;
    }
    for (d, &p) in POW10.iter().enumerate() {
        let n = round_cheap(x * p);
        if n.abs() >= 1e15 && (n.abs() >= 9_007_199_254_740_992.0 || ulp * p >= 1.0) {
            return false;
        }
        if n / p == x {
            push_decimal(out, x < 0.0, n.abs() as u64, d);
            return true;
        }
    }
    false
}

/// `a`·10^-d (with its sign) positionally: the integer part, ".", the decimals without
/// trailing zeros (at least one digit: "70.0").
fn push_decimal(out: &mut String, negative: bool, a: u64, d: usize) {
    let scale = 10u64.pow(d as u32);
    if negative {
        out.push('-');
    }
    push_u64(out, a / scale);
    out.push('.');
    let mut frac = a % scale;
    if d == 0 || frac == 0 {
        out.push('0');
        return;
    }
    // d digits with their leading zeros, without trailing zeros
    let mut digits = d;
    while frac.is_multiple_of(10) {
        frac /= 10;
        digits -= 1;
    }
    let width = frac.checked_ilog10().map_or(1, |l| l as usize + 1);
    for _ in width..digits {
        out.push('0');
    }
    push_u64(out, frac);
}

/// `y` rounded to a nearby integer, without the libm call `f64::round` makes on plain x86-64
/// (any nearby integer does: the caller checks the result exactly). Saturates out of range.
#[inline]
fn round_cheap(y: f64) -> f64 {
    let t = y as i64; // truncates toward zero
    let frac = y - t as f64;
    let n = if frac >= 0.5 {
        t.saturating_add(1)
    } else if frac <= -0.5 {
        t.saturating_sub(1)
    } else {
        t
    };
    n as f64
}

/// `push_positional` through `Display` (and `layout` for the possible halfway cases).
fn push_positional_fmt(out: &mut String, x: f64, lo: i32) {
    let start = out.len();
    let _ = write!(out, "{x}");
    let text = &out.as_bytes()[start..];
    // 16+ significant digits may be a halfway case `shortest` settles as Python does
    let significant = text
        .iter()
        .skip_while(|&&c| !matches!(c, b'1'..=b'9'))
        .filter(|c| c.is_ascii_digit())
        .count();
    if significant >= 16 && tie_possible(x.abs()) {
        out.truncate(start);
        layout(out, x, lo, lo == -4);
    } else if !text.contains(&b'.') {
        out.push_str(".0");
    }
}

/// Python's `repr(x)` (and `str(x)`, and `f"{x}"`).
pub fn py_repr(x: f64) -> String {
    let mut s = String::new();
    push_py_repr(&mut s, x);
    s
}

pub fn push_py_repr(out: &mut String, x: f64) {
    if (1e-4..1e16).contains(&x.abs()) {
        push_positional(out, x, -4);
    } else if x.is_nan() {
        out.push_str("nan");
    } else if x.is_infinite() {
        out.push_str(if x > 0.0 { "inf" } else { "-inf" });
    } else {
        layout(out, x, -4, true);
    }
}

/// orjson's text of a float (NaN and infinities are `null`, as orjson writes them).
pub fn push_json_float(out: &mut String, x: f64) {
    if (1e-5..1e16).contains(&x.abs()) {
        push_positional(out, x, -5);
    } else if !x.is_finite() {
        out.push_str("null");
    } else {
        layout(out, x, -5, false);
    }
}

/// Python's `f"{x:.{n}f}"`.
pub fn py_fixed(x: f64, n: usize) -> String {
    format!("{:.*}", n, x)
}

/// Python's `round(x, n)` for n >= 0.
pub fn py_round(x: f64, n: usize) -> f64 {
    if !x.is_finite() {
        return x;
    }
    py_fixed(x, n).parse().unwrap_or(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repr_matches_python() {
        let cases: &[(f64, &str)] = &[
            (70.0, "70.0"),
            (1e-5, "1e-05"),
            (0.0001, "0.0001"),
            (1e16, "1e+16"),
            (1234567890123456.8, "1234567890123456.8"),
            (1.5e300, "1.5e+300"),
            (0.59, "0.59"),
            (-0.0, "-0.0"),
            (5e-324, "5e-324"),
            (1763700000.00659, "1763700000.00659"),
            // exactly 926001165992679.25: halfway, the even neighbour
            (926001165992679.2, "926001165992679.2"),
            (-93534475038340.62, "-93534475038340.62"),
        ];
        for (x, want) in cases {
            assert_eq!(py_repr(*x), *want, "{x}");
        }
    }

    #[test]
    fn json_matches_orjson() {
        let cases: &[(f64, &str)] = &[
            (70.0, "70.0"),
            (1e-5, "0.00001"),
            (2.5e-5, "0.000025"),
            (1e-6, "1e-6"),
            (1e16, "1e+16"),
            (1e15, "1000000000000000.0"),
            (1.7976931348623157e308, "1.7976931348623157e+308"),
            (f64::NAN, "null"),
        ];
        for (x, want) in cases {
            let mut s = String::new();
            push_json_float(&mut s, *x);
            assert_eq!(s, *want, "{x}");
        }
    }

    /// The short-decimal fast path against `Display` on decimals of every length and on
    /// random doubles (where it must either agree or decline).
    #[test]
    fn short_decimals_as_display() {
        let mut seed = 0x9E37_79B9_7F4A_7C15_u64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let (mut fast, mut slow) = (String::new(), String::new());
        let mut taken = 0;
        for i in 0..300_000 {
            let x = if i % 3 == 2 {
                // candump times: 10 integer digits and 6 decimals (16-17 digits)
                let n = 1_000_000_000_000_000 + next() % 3_000_000_000_000_000;
                n as f64 / 1e6
            } else if i % 3 == 0 {
                let d = (next() % 8) as i32;
                let n = (next() % 10u64.pow((next() % 16) as u32 + 1)) as f64;
                let x = n / 10f64.powi(d);
                if next() % 2 == 0 {
                    -x
                } else {
                    x
                }
            } else {
                f64::from_bits(next() >> 2) // positive, of every exponent up to ~1e77
            };
            if !(1e-4..1e16).contains(&x.abs()) {
                continue;
            }
            fast.clear();
            slow.clear();
            push_positional_fmt(&mut slow, x, -4);
            if push_short_decimal(&mut fast, x) {
                taken += 1;
                assert_eq!(fast, slow, "{x:e}");
            }
        }
        assert!(taken > 150_000, "{taken}");
    }

    #[test]
    fn round_half_even_on_exact_value() {
        assert_eq!(py_round(0.125, 2), 0.12);
        assert_eq!(py_round(2.675, 2), 2.67);
        assert_eq!(py_round(0.375, 2), 0.38);
        assert_eq!(py_fixed(2.5, 0), "2");
    }
}
