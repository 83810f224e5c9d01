//! The environment the vcan tests of every crate read, as `scripts/vcan-tests.sh` sets it: which
//! interface, and how much headroom a slow guest (User-Mode Linux, QEMU) needs. One reading for the
//! driver's tests here and the application's.

/// The CAN interface the vcan tests use: `FORCECELL_VCAN`, else `vcan0`.
pub fn interface() -> String {
    std::env::var("FORCECELL_VCAN").unwrap_or_else(|_| "vcan0".into())
}

/// The headroom for slow guests, `FORCECELL_VCAN_TIME_SCALE`: 1 to 100, 1 when unset. Deadlines
/// and turnarounds are multiplied by it.
pub fn time_scale() -> Result<u32, String> {
    parse_scale(std::env::var("FORCECELL_VCAN_TIME_SCALE").ok().as_deref())
}

fn parse_scale(value: Option<&str>) -> Result<u32, String> {
    match value {
        None => Ok(1),
        Some(s) => s
            .parse::<u32>()
            .ok()
            .filter(|k| (1..=100).contains(k))
            .ok_or_else(|| format!("FORCECELL_VCAN_TIME_SCALE must be 1 to 100, not {s:?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::parse_scale;

    #[test]
    fn the_scale_is_one_unless_set_and_refuses_what_is_out_of_range() {
        assert_eq!(parse_scale(None), Ok(1));
        assert_eq!(parse_scale(Some("20")), Ok(20));
        for bad in ["0", "101", "-1", "2.5", ""] {
            let e = parse_scale(Some(bad)).unwrap_err();
            assert!(e.contains("1 to 100"), "{bad}: {e}");
        }
    }
}
