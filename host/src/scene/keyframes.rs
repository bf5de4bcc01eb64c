//! `[[keyframe]]`: any number or array of numbers in a scene file, set at
//! times and interpolated linearly between them (held before the first
//! and after the last), so an animation can move the camera, the lights,
//! the objects or the sun. Each keyframe is `at = seconds` and dotted paths
//! to the fields it sets:
//!
//! ```toml
//! [[keyframe]]
//! at = 0.0
//! "camera.position" = [0.0, 2.0, 10.0]
//! "sky.sun_zenith_deg" = 60.0
//!
//! [[keyframe]]
//! at = 4.0
//! "camera.position" = [6.0, 2.0, 8.0]
//! "spotlight[1].direction" = [0.2, -1.0, 0.0]
//! ```
//!
//! A path names a field the file gives (`object[2].center`); an integer
//! field is rounded. Keyframes work on the file's TOML before it is read
//! into the scene, so every field's checks apply to the values they give.

use anyhow::{anyhow, bail, Result};
use toml::{Table, Value};

/// The keyframes of a file, by time: `(at, [(path, value)])`.
pub type Keyframes = Vec<(f64, Vec<(String, Value)>)>;

/// One segment of a path: a key, then any number of `[index]`es.
fn segments(path: &str) -> Result<Vec<(String, Vec<usize>)>> {
    let mut out = Vec::new();
    for part in path.split('.') {
        let (key, rest) = part.split_once('[').map_or((part, ""), |(k, r)| (k, r));
        if key.is_empty() {
            bail!("expected a dotted path of keys (camera.position, object[2].center), got {path:?}");
        }
        let mut indices = Vec::new();
        if !rest.is_empty() {
            for idx in format!("[{rest}").split('[').skip(1) {
                let n = idx.strip_suffix(']').and_then(|n| n.parse().ok());
                indices.push(n.ok_or_else(|| anyhow!("{path:?}: expected [index] with a whole number"))?);
            }
        }
        out.push((key.to_string(), indices));
    }
    Ok(out)
}

/// The value at `path` in `table`, mutable.
fn lookup<'a>(table: &'a mut Table, path: &str) -> Result<&'a mut Value> {
    let segs = segments(path)?;
    let missing = || anyhow!("{path:?}: the scene file has no such field to animate");
    let index = |mut v: &'a mut Value, indices: &[usize]| -> Result<&'a mut Value> {
        for &i in indices {
            v = match v {
                Value::Array(a) => a.get_mut(i).ok_or_else(missing)?,
                _ => return Err(missing()),
            };
        }
        Ok(v)
    };
    let (first, rest) = segs.split_first().ok_or_else(missing)?;
    let mut here = index(table.get_mut(&first.0).ok_or_else(missing)?, &first.1)?;
    for (key, indices) in rest {
        here = match here {
            Value::Table(t) => index(t.get_mut(key).ok_or_else(missing)?, indices)?,
            _ => return Err(missing()),
        };
    }
    Ok(here)
}

/// `a + (b - a) s` for numbers and equal-length arrays of numbers; the
/// result takes the kind (integer or float) of `like`.
fn blend(a: &Value, b: &Value, s: f64, like: &Value, path: &str) -> Result<Value> {
    let number = |v: &Value| match v {
        Value::Integer(i) => Some(*i as f64),
        Value::Float(f) => Some(*f),
        _ => None,
    };
    match (a, b, like) {
        (Value::Array(x), Value::Array(y), Value::Array(l)) if x.len() == y.len() && x.len() == l.len() => {
            let items = x.iter().zip(y).zip(l).map(|((x, y), l)| blend(x, y, s, l, path)).collect::<Result<_>>()?;
            Ok(Value::Array(items))
        }
        _ => {
            let (Some(x), Some(y)) = (number(a), number(b)) else {
                bail!("{path:?}: expected numbers or arrays of numbers of the field's length, got {a} and {b}");
            };
            let v = x + (y - x) * s;
            match like {
                Value::Integer(_) => Ok(Value::Integer(v.round() as i64)),
                Value::Float(_) => Ok(Value::Float(v)),
                _ => bail!("{path:?}: the field is not a number or an array of numbers"),
            }
        }
    }
}

/// Removes `keyframe` from `table` and returns the keyframes, each `(at,
/// [(path, value)])`, sorted by time; errors name the keyframe.
pub fn take(table: &mut Table) -> Result<Keyframes> {
    let Some(list) = table.remove("keyframe") else { return Ok(Vec::new()) };
    let Value::Array(list) = list else { bail!("keyframe: expected [[keyframe]] tables") };
    let mut out = Vec::new();
    for (i, k) in list.into_iter().enumerate() {
        let Value::Table(mut k) = k else { bail!("keyframe[{i}]: expected a table") };
        let at = match k.remove("at") {
            Some(Value::Float(f)) if f.is_finite() && f >= 0.0 => f,
            Some(Value::Integer(n)) if n >= 0 => n as f64,
            other => bail!("keyframe[{i}].at: expected a time in seconds (>= 0), got {other:?}"),
        };
        out.push((at, k.into_iter().collect::<Vec<_>>()));
    }
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(out)
}

/// Sets every animated field of `table` to its value at time `t` (s).
pub fn apply(table: &mut Table, keyframes: &Keyframes, t: f64) -> Result<()> {
    let mut paths: Vec<&str> = keyframes.iter().flat_map(|(_, s)| s.iter().map(|(p, _)| p.as_str())).collect();
    paths.sort();
    paths.dedup();
    for path in paths {
        let keys: Vec<(f64, &Value)> =
            keyframes.iter().filter_map(|(at, s)| s.iter().find(|(p, _)| p == path).map(|(_, v)| (*at, v))).collect();
        let field = lookup(table, path).map_err(|e| anyhow!("keyframe: {e}"))?;
        let next = keys.iter().position(|(at, _)| *at > t);
        let value = match next {
            None => blend(keys[keys.len() - 1].1, keys[keys.len() - 1].1, 0.0, field, path)?,
            Some(0) => blend(keys[0].1, keys[0].1, 0.0, field, path)?,
            Some(j) => {
                let ((t0, a), (t1, b)) = (keys[j - 1], keys[j]);
                blend(a, b, (t - t0) / (t1 - t0), field, path)?
            }
        };
        *field = value;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(text: &str) -> Table {
        text.parse().unwrap()
    }

    #[test]
    fn fields_are_interpolated_linearly_and_held_outside_the_keys() {
        let text = r#"
            a = [0.0, 0.0]
            n = 3
            [[thing]]
            x = 1.0
            [[keyframe]]
            at = 1.0
            a = [0.0, 10.0]
            "thing[0].x" = 2.0
            n = 4
            [[keyframe]]
            at = 3.0
            a = [4.0, 20.0]
            "thing[0].x" = 6.0
            n = 8
        "#;
        let mut t = table(text);
        let keys = take(&mut t).unwrap();
        let at = |time: f64| {
            let mut c = t.clone();
            apply(&mut c, &keys, time).unwrap();
            c
        };
        let v = at(2.0);
        assert_eq!(v["a"], Value::Array(vec![Value::Float(2.0), Value::Float(15.0)]));
        assert_eq!(v["thing"][0]["x"], Value::Float(4.0));
        assert_eq!(v["n"], Value::Integer(6));
        assert_eq!(at(0.0)["thing"][0]["x"], Value::Float(2.0));
        assert_eq!(at(9.0)["thing"][0]["x"], Value::Float(6.0));
        assert!(!at(2.0).contains_key("keyframe"));
    }

    #[test]
    fn a_path_the_file_lacks_or_a_wrong_shape_is_an_error_naming_it() {
        for (body, needle) in [
            ("[[keyframe]]\nat = 0.0\n\"camera.fov\" = 1.0", "camera.fov"),
            ("a = [1.0, 2.0]\n[[keyframe]]\nat = 0.0\na = [1.0]", "\"a\""),
            ("a = 1.0\n[[keyframe]]\nat = -1.0\na = 2.0", "keyframe[0].at"),
        ] {
            let mut t = table(body);
            let err = take(&mut t).and_then(|k| apply(&mut t, &k, 0.0)).unwrap_err().to_string();
            assert!(err.contains(needle), "{body}: {err}");
        }
    }
}
