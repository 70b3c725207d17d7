//! Robot names as an operator reads them: the number a name ends with
//! (`robot_12` -> 12, which the router gives the robot as its id) and the
//! natural order of names, where digit runs compare as numbers
//! (`robot_2` before `robot_10`).

use std::cmp::Ordering;

/// The number a name ends with, if it has one in `1..=65535`: `robot_12`
/// -> 12, `rover-7` -> 7, `r2d2` -> 2; `rover`, `robot_0` and `robot_70000`
/// have none.
pub fn trailing_number(name: &str) -> Option<u16> {
    let digits = name.len() - name.trim_end_matches(|c: char| c.is_ascii_digit()).len();
    let tail = &name[name.len() - digits..];
    let n: u16 = tail.parse().ok()?;
    (n > 0).then_some(n)
}

/// Natural order: runs of ASCII digits compare by value (`robot_2` <
/// `robot_10`), everything else byte by byte. Names equal by value but
/// spelled differently (`r01`, `r1`) order by their bytes, so the order is
/// total and agrees with equality.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (x, y) = (a.as_bytes(), b.as_bytes());
    let (mut i, mut j) = (0, 0);
    while i < x.len() && j < y.len() {
        if x[i].is_ascii_digit() && y[j].is_ascii_digit() {
            let (si, sj) = (i, j);
            while i < x.len() && x[i].is_ascii_digit() {
                i += 1;
            }
            while j < y.len() && y[j].is_ascii_digit() {
                j += 1;
            }
            let (p, q) = (trim_zeros(&x[si..i]), trim_zeros(&y[sj..j]));
            let by_value = p.len().cmp(&q.len()).then_with(|| p.cmp(q));
            if by_value != Ordering::Equal {
                return by_value;
            }
        } else {
            if x[i] != y[j] {
                return x[i].cmp(&y[j]);
            }
            i += 1;
            j += 1;
        }
    }
    (x.len() - i).cmp(&(y.len() - j)).then_with(|| x.cmp(y))
}

fn trim_zeros(digits: &[u8]) -> &[u8] {
    let zeros = digits.iter().take_while(|&&d| d == b'0').count();
    &digits[zeros..]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_name_ends_with_its_number() {
        assert_eq!(trailing_number("robot_12"), Some(12));
        assert_eq!(trailing_number("rover-7"), Some(7));
        assert_eq!(trailing_number("r2d2"), Some(2));
        assert_eq!(trailing_number("robot_007"), Some(7));
        assert_eq!(trailing_number("rover"), None);
        assert_eq!(trailing_number("robot_0"), None);
        assert_eq!(trailing_number("robot_70000"), None);
        assert_eq!(trailing_number(""), None);
    }

    #[test]
    fn numbers_in_names_sort_by_value() {
        let mut names = vec![
            "robot_10",
            "robot_2",
            "robot_1",
            "rover",
            "robot_100",
            "robot_11",
            "r01",
            "r1",
        ];
        names.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            names,
            [
                "r01",
                "r1",
                "robot_1",
                "robot_2",
                "robot_10",
                "robot_11",
                "robot_100",
                "rover"
            ]
        );
    }

    #[test]
    fn natural_order_is_total() {
        for (a, b) in [("a1b", "a1"), ("a", "a0"), ("x9", "x09"), ("", "0")] {
            assert_eq!(natural_cmp(a, b), natural_cmp(b, a).reverse(), "{a} {b}");
            assert_ne!(natural_cmp(a, b), Ordering::Equal, "{a} {b}");
        }
        assert_eq!(natural_cmp("robot_3", "robot_3"), Ordering::Equal);
    }
}
