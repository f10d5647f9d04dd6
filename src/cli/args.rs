//! Parsers for the command line's compound values; each error names what was expected.

use glam::Vec3;

use hdov::Aabb;

fn floats(s: &str, n: usize, what: &str) -> Result<Vec<f32>, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>().map_err(|_| format!("'{x}' is not a number in {what} '{s}'")))
        .collect::<Result<_, _>>()?;
    if v.len() != n {
        return Err(format!("expected {n} comma-separated numbers for {what}, got {} in '{s}'", v.len()));
    }
    if let Some(x) = v.iter().find(|x| !x.is_finite()) {
        return Err(format!("{what} '{s}' holds a non-finite value {x}"));
    }
    Ok(v)
}

/// `X,Y,Z`.
pub fn parse_vec3(s: &str) -> Result<Vec3, String> {
    floats(s, 3, "a point X,Y,Z").map(|v| Vec3::new(v[0], v[1], v[2]))
}

/// `X0,Y0,Z0,X1,Y1,Z1`, a non-empty box.
pub fn parse_region(s: &str) -> Result<Aabb, String> {
    let v = floats(s, 6, "a region X0,Y0,Z0,X1,Y1,Z1")?;
    let b = Aabb::from_array([v[0], v[1], v[2], v[3], v[4], v[5]]);
    if b.min.cmpgt(b.max).any() {
        return Err(format!("region '{s}' has a minimum above its maximum"));
    }
    Ok(b)
}

/// `NXxNY` or `NXxNYxNZ`: positive counts.
pub fn parse_dims<const N: usize>(s: &str) -> Result<[u32; N], String> {
    let v: Vec<u32> = s
        .split(['x', 'X'])
        .map(|x| x.trim().parse::<u32>().ok().filter(|&n| n > 0))
        .collect::<Option<_>>()
        .ok_or_else(|| format!("'{s}' is not {N} positive counts separated by 'x'"))?;
    v.try_into().map_err(|_| format!("expected {N} counts separated by 'x', got '{s}'"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_refuses() {
        assert_eq!(parse_vec3("1,2.5,-3").unwrap(), Vec3::new(1.0, 2.5, -3.0));
        assert!(parse_vec3("1,2").unwrap_err().contains("3 comma-separated"));
        assert!(parse_vec3("1,nan,2").unwrap_err().contains("non-finite"));
        assert!(parse_vec3("1,a,2").unwrap_err().contains("'a'"));
        assert_eq!(parse_dims::<3>("4x1x8").unwrap(), [4, 1, 8]);
        assert_eq!(parse_dims::<2>("10X12").unwrap(), [10, 12]);
        assert!(parse_dims::<3>("4x0x8").is_err());
        assert!(parse_dims::<3>("4x8").is_err());
        assert!(parse_region("0,0,0,1,1,1").is_ok());
        assert!(parse_region("1,0,0,0,1,1").unwrap_err().contains("minimum above"));
    }
}
