//! Parsers for the compound values on the tools' command lines, for clap's `value_parser`: a bad
//! value is a clap error (one line naming the argument, exit status 2), and each message says
//! what was expected.

use hdov::city::{CityScale, WalkKind};
use hdov::{LodRule, Shard};

/// `N` positive whole numbers separated by any of `separators`; `shape` and `example` say what
/// was expected.
fn counts<const N: usize>(s: &str, separators: &[char], shape: &str, example: &str) -> Result<[u32; N], String> {
    let counts: Vec<u32> = s
        .split(separators)
        .map(|x| x.trim().parse::<u32>().ok().filter(|&n| n > 0))
        .collect::<Option<_>>()
        .ok_or_else(|| format!("'{s}' is not {shape} in positive whole numbers, e.g. {example}"))?;
    counts.try_into().map_err(|_| format!("'{s}' is not {shape}, e.g. {example}"))
}

/// `WIDTHxHEIGHT` (or `WIDTHXHEIGHT`): two positive whole numbers of pixels, e.g. `640x360`.
pub fn size(s: &str) -> Result<[u32; 2], String> {
    counts(s, &['x', 'X'], "WIDTHxHEIGHT", "640x360")
}

/// `X,Y,Z`: three positive whole numbers, e.g. `8,1,8`.
pub fn triple(s: &str) -> Result<[u32; 3], String> {
    counts(s, &[','], "X,Y,Z", "8,1,8")
}

/// A generated city's scale: `tiny`, `small`, `default`, `large` or `huge`.
pub fn city_scale(s: &str) -> Result<CityScale, String> {
    s.parse::<CityScale>().map_err(|e| e.to_string())
}

/// A query's LOD rule, as `hdov query --lod-rule` takes it (e.g. `dov`, `screen:2`).
pub fn lod_rule(s: &str) -> Result<LodRule, String> {
    s.parse::<LodRule>()
}

/// `I/N`: the I-th of N equal parts of a grid's cells (`hdov build --shard`).
pub fn shard(s: &str) -> Result<Shard, String> {
    s.parse::<Shard>()
}

/// One of the recorded walks: `straight`, `turning` or `back-and-forth`.
pub fn walk_kind(s: &str) -> Result<WalkKind, String> {
    s.parse::<WalkKind>()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_refuses() {
        assert_eq!(size("640x360").unwrap(), [640, 360]);
        assert_eq!(size("320X200").unwrap(), [320, 200]);
        assert!(size("640").is_err());
        assert!(size("640x0").is_err());
        assert!(size("640x360x2").is_err());
        assert!(size("ax360").unwrap_err().contains("WIDTHxHEIGHT"));
        assert_eq!(triple("8,1,8").unwrap(), [8, 1, 8]);
        assert!(triple("8,1").is_err());
        assert!(triple("8,x,8").is_err());
        assert!(city_scale("small").is_ok());
        assert!(city_scale("enormous").is_err());
        assert!(shard("0/8").is_ok());
        assert!(shard("8").is_err());
    }
}
