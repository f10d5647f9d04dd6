//! Queries as text: a point `X,Y,Z`, a box, grid counts `NXxNYxNZ`, and a URL's query string
//! (`at=…&eta=…`, `path=X,Y,Z;X,Y,Z;…`). The command line and `hdov serve` read through here, so
//! both accept and refuse the same strings with the same one-line reasons, and the `url_query`
//! fuzz target feeds it hostile ones. Every error names what was expected.

use std::collections::HashMap;
use std::str::FromStr;

use glam::Vec3;

use crate::camera::Camera;
use crate::error::Param;
use crate::geom::Aabb;
use crate::query::{LodRule, Mode, QueryParams};
use crate::scene::standable::EyeHeights;
use hdov_storage::LayoutKind;
pub use hdov_storage::names::quoted;

/// The keys of a point query (`/query`).
pub const QUERY_KEYS: &[&str] = &["at", "look", "fov", "eta", "mode", "lod_rule", "layout", "budget", "tau"];
/// The keys of a walk (`/walk`): a path instead of a point.
pub const WALK_KEYS: &[&str] = &["path", "look", "fov", "eta", "mode", "lod_rule", "layout", "budget", "tau"];

/// `n` comma-separated finite numbers.
fn floats(s: &str, n: usize, what: &str) -> Result<Vec<f32>, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>().map_err(|_| format!("{} is not a number in {what} {}", quoted(x), quoted(s))))
        .collect::<Result<_, _>>()?;
    if v.len() != n {
        return Err(format!("expected {n} comma-separated numbers for {what}, got {} in {}", v.len(), quoted(s)));
    }
    if let Some(x) = v.iter().find(|x| !x.is_finite()) {
        return Err(format!("{what} {} holds a non-finite value {x}", quoted(s)));
    }
    Ok(v)
}

/// `X,Y,Z`.
pub fn parse_point(s: &str) -> Result<Vec3, String> {
    floats(s, 3, "a point X,Y,Z").map(|v| Vec3::new(v[0], v[1], v[2]))
}

/// `X0,Y0,Z0,X1,Y1,Z1`, a non-empty box.
pub fn parse_box(s: &str) -> Result<Aabb, String> {
    let v = floats(s, 6, "a region X0,Y0,Z0,X1,Y1,Z1")?;
    let b = Aabb::from_array([v[0], v[1], v[2], v[3], v[4], v[5]]);
    if b.min.cmpgt(b.max).any() {
        return Err(format!("region {} has a minimum above its maximum", quoted(s)));
    }
    Ok(b)
}

/// 16 numbers, a column-major 4 × 4 matrix.
pub fn parse_matrix(s: &str) -> Result<glam::Mat4, String> {
    floats(s, 16, "a column-major 4x4 matrix").map(|v| glam::Mat4::from_cols_slice(&v))
}

/// `LOW,HIGH`: eye heights above a floor (checked when a grid is made from them).
pub fn parse_eye_heights(s: &str) -> Result<EyeHeights, String> {
    floats(s, 2, "eye heights LOW,HIGH").map(|v| EyeHeights { low: v[0], high: v[1] })
}

/// `NXxNY` or `NXxNYxNZ`: positive counts.
pub fn parse_dims<const N: usize>(s: &str) -> Result<[u32; N], String> {
    let v: Vec<u32> = s
        .split(['x', 'X'])
        .map(|x| x.trim().parse::<u32>().ok().filter(|&n| n > 0))
        .collect::<Option<_>>()
        .ok_or_else(|| format!("{} is not {N} positive counts separated by 'x'", quoted(s)))?;
    v.try_into().map_err(|_| format!("expected {N} counts separated by 'x', got {}", quoted(s)))
}

/// The URL key that sets a library parameter (the camera is `look`; the others keep their names).
pub fn url_key(param: Param) -> &'static str {
    match param {
        Param::Camera => "look",
        p => p.name(),
    }
}

/// A URL's query string as `key=value` pairs, each key at most once and one of those the route
/// knows, read into the library's values on demand.
#[derive(Debug)]
pub struct UrlQuery(HashMap<String, String>);

impl UrlQuery {
    /// The pairs of `raw` (percent-decoded); an unknown or repeated key is refused.
    pub fn parse(raw: &str, known: &[&str]) -> Result<UrlQuery, String> {
        let list: Vec<(String, String)> =
            serde_urlencoded::from_str(raw).map_err(|e| format!("malformed query string: {e}"))?;
        let mut out = HashMap::new();
        for (k, v) in list {
            if !known.contains(&k.as_str()) {
                return Err(format!("unknown parameter {} ({})", quoted(&k), known.join(", ")));
            }
            if out.insert(k.clone(), v).is_some() {
                return Err(format!("parameter {} given twice", quoted(&k)));
            }
        }
        Ok(UrlQuery(out))
    }

    /// The value of `key` parsed by `parse`, its error prefixed by the key; `None` if absent.
    pub fn value<T>(&self, key: &str, parse: impl FnOnce(&str) -> Result<T, String>) -> Result<Option<T>, String> {
        self.0.get(key).map(|v| parse(v).map_err(|r| format!("{key}: {r}"))).transpose()
    }

    /// The value of `key` as a number; `what` says which (`"a count"`).
    pub fn number<T: FromStr>(&self, key: &str, what: &str) -> Result<Option<T>, String> {
        self.value(key, |s| s.parse::<T>().map_err(|_| format!("{} is not {what}", quoted(s))))
    }

    /// The point `key=X,Y,Z`, which must be there.
    pub fn point(&self, key: &str) -> Result<Vec3, String> {
        self.value(key, parse_point)?.ok_or_else(|| format!("{key}: missing ({key}=X,Y,Z)"))
    }

    /// The walk `path=X,Y,Z;X,Y,Z;…`, which must be there.
    pub fn path(&self) -> Result<Vec<Vec3>, String> {
        let path = self.0.get("path").ok_or("path: missing (path=X,Y,Z;X,Y,Z;…)")?;
        path.split(';').enumerate().map(|(k, v)| parse_point(v).map_err(|r| format!("path: step {k}: {r}"))).collect()
    }

    /// The query a request asks, from its `look`, `fov`, `eta`, `mode`, `lod_rule`, `layout`,
    /// `budget` and `tau` (each as the command line parses it); the rest as
    /// [`QueryParams::default`]. The library checks the values' ranges when it runs the query.
    pub fn query_params(&self) -> Result<QueryParams, String> {
        let look = self.value("look", parse_point)?;
        let fov = self.number::<f32>("fov", "a number of degrees")?;
        let defaults = QueryParams::default();
        Ok(QueryParams {
            mode: self.value("mode", str::parse::<Mode>)?.unwrap_or(defaults.mode),
            eta: self.number("eta", "a number")?.unwrap_or(defaults.eta),
            budget: self.number("budget", "a count of faces")?.unwrap_or(defaults.budget),
            tau: self.number("tau", "a number of pixels")?.unwrap_or(defaults.tau),
            lod_rule: self.value("lod_rule", str::parse::<LodRule>)?.unwrap_or(defaults.lod_rule),
            layout: self.value("layout", |s| s.parse::<LayoutKind>().map_err(|e| e.to_string()))?,
            camera: look.map(|look| Camera { look, fov_y_deg: fov.unwrap_or(60.0), ..Camera::default() }),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_refuses() {
        assert_eq!(parse_point("1,2.5,-3").unwrap(), Vec3::new(1.0, 2.5, -3.0));
        assert!(parse_point("1,2").unwrap_err().contains("3 comma-separated"));
        assert!(parse_point("1,nan,2").unwrap_err().contains("non-finite"));
        assert!(parse_point("1,a,2").unwrap_err().contains("'a'"));
        assert_eq!(parse_dims::<3>("4x1x8").unwrap(), [4, 1, 8]);
        assert_eq!(parse_dims::<2>("10X12").unwrap(), [10, 12]);
        assert!(parse_dims::<3>("4x0x8").is_err());
        assert!(parse_dims::<3>("4x8").is_err());
        assert!(parse_box("0,0,0,1,1,1").is_ok());
        assert!(parse_box("1,0,0,0,1,1").unwrap_err().contains("minimum above"));
    }

    #[test]
    fn url_queries_read_what_they_name_and_refuse_the_rest() {
        let q = UrlQuery::parse("at=1,2,3&eta=0.1&mode=naive&look=0%2C0%2C-1&fov=45", QUERY_KEYS).unwrap();
        assert_eq!(q.point("at").unwrap(), Vec3::new(1.0, 2.0, 3.0));
        let p = q.query_params().unwrap();
        assert_eq!((p.eta, p.mode), (0.1, Mode::Naive));
        let camera = p.camera.unwrap();
        assert_eq!((camera.look, camera.fov_y_deg), (Vec3::NEG_Z, 45.0));

        assert_eq!(UrlQuery::parse("at=1,2,3&at=1,2,3", QUERY_KEYS).unwrap_err(), "parameter 'at' given twice");
        assert!(UrlQuery::parse("where=1", QUERY_KEYS).unwrap_err().starts_with("unknown parameter 'where'"));
        assert_eq!(UrlQuery::parse("", QUERY_KEYS).unwrap().point("at").unwrap_err(), "at: missing (at=X,Y,Z)");
        let bad = UrlQuery::parse("at=1,2,3&eta=lots", QUERY_KEYS).unwrap();
        assert_eq!(bad.query_params().unwrap_err(), "eta: 'lots' is not a number");
        let bad = UrlQuery::parse("at=1,2,3&mode=guess", QUERY_KEYS).unwrap();
        assert!(bad.query_params().unwrap_err().starts_with("mode: "));

        let walk = UrlQuery::parse("path=0,0,0;1,0,0", WALK_KEYS).unwrap();
        assert_eq!(walk.path().unwrap(), vec![Vec3::ZERO, Vec3::X]);
        let bad = UrlQuery::parse("path=0,0,0;1,0", WALK_KEYS).unwrap();
        assert!(bad.path().unwrap_err().starts_with("path: step 1: "));

        // Whatever a client sends comes back on one line, and short.
        let e = UrlQuery::parse("a%0Ab=1", QUERY_KEYS).unwrap_err();
        assert!(e.starts_with("unknown parameter 'a\\nb'"), "{e}");
        let e = UrlQuery::parse(&format!("at={}", "x".repeat(5000)), QUERY_KEYS).unwrap().point("at").unwrap_err();
        assert!(e.len() < 200 && e.contains('…'), "{e}");
    }
}
