//! Human-readable sizes for command-line flags such as `--cache-max-size 2G`.

/// Parses a size in bytes: a decimal number (fractions allowed with a unit) followed by an
/// optional unit, case-insensitive, with optional spaces between: none or `B` = bytes,
/// `K`/`KB`/`KiB` = 1024, `M`/`MB`/`MiB` = 1024², `G`/`GB`/`GiB` = 1024³, `T`/`TB`/`TiB` =
/// 1024⁴. All units are powers of 1024 (so `KB` means 1024 too). Fractional results are
/// rounded down: `"1.5GiB"` = 1610612736, `"0.1K"` = 102. Examples: `"1024"`, `"10k"`,
/// `"500M"`, `"2G"`. Errors (with a message for the user) on an empty string, a missing
/// number, an unknown unit, a fraction of a plain byte count, or a result above `u64::MAX`.
pub fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let num_end = t.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(t.len());
    let (num, unit) = (&t[..num_end], t[num_end..].trim());
    let (int, frac) = match num.split_once('.') {
        Some((i, f)) => (i, f),
        None => (num, ""),
    };
    if int.is_empty() && frac.is_empty() {
        return Err(format!("size {s:?}: expected a number, e.g. 500M, 2G, 1.5GiB, 1024"));
    }
    if frac.contains('.') {
        return Err(format!("size {s:?}: more than one decimal point"));
    }
    let shift = match unit.to_ascii_lowercase().as_str() {
        "" | "b" => 0,
        "k" | "kb" | "kib" => 10,
        "m" | "mb" | "mib" => 20,
        "g" | "gb" | "gib" => 30,
        "t" | "tb" | "tib" => 40,
        _ => return Err(format!("size {s:?}: unknown unit {unit:?} (use B, K, M, G or T; powers of 1024)")),
    };
    if shift == 0 && !frac.is_empty() {
        return Err(format!("size {s:?}: a byte count has no fraction"));
    }
    let too_big = || format!("size {s:?}: too large");
    let int: u64 = if int.is_empty() { 0 } else { int.parse().map_err(|_| too_big())? };
    let mut bytes = int.checked_mul(1u64 << shift).ok_or_else(too_big)?;
    // Fraction exactly, in integers: digits * 2^shift / 10^digits, rounded down. At most 19
    // digits are used so 10^digits fits; later ones cannot change a result below 2^40 * 10.
    let frac = &frac[..frac.len().min(19)];
    if !frac.is_empty() {
        let digits: u128 = frac.parse().map_err(|_| format!("size {s:?}: bad fraction"))?;
        let part = (digits << shift) / 10u128.pow(frac.len() as u32);
        bytes = bytes.checked_add(part as u64).ok_or_else(too_big)?;
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::parse_size;

    #[test]
    fn accepted() {
        let cases: &[(&str, u64)] = &[
            ("1024", 1024),
            ("0", 0),
            ("12B", 12),
            ("10k", 10 * 1024),
            ("10K", 10 * 1024),
            ("10KB", 10 * 1024),
            ("10 KiB", 10 * 1024),
            ("500M", 500 << 20),
            ("500mb", 500 << 20),
            ("2G", 2 << 30),
            ("2gib", 2 << 30),
            ("1.5GiB", 1_610_612_736),
            ("1.5G", 3 << 29),
            (".5M", 1 << 19),
            ("0.1K", 102),
            ("1T", 1 << 40),
            ("  3M  ", 3 << 20),
            ("16777215T", 16_777_215u64 << 40),
        ];
        for &(s, want) in cases {
            assert_eq!(parse_size(s), Ok(want), "{s:?}");
        }
    }

    #[test]
    fn rejected() {
        for s in [
            "",
            " ",
            "M",
            "G5",
            "-1",
            "1.5",
            "1..5M",
            "1.2.3G",
            "10X",
            "10 MBs",
            "1P",
            "16777216T",
            "99999999999999999999",
        ] {
            assert!(parse_size(s).is_err(), "{s:?} accepted as {:?}", parse_size(s));
        }
    }
}
