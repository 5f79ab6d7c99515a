//! The `--policy` mini-language: `depth=16,gran=object,range=direction,look=any,read=1024k,size=16`
//! (Funkhouser §5.2's parameters, as the load tester's sweep names them).

use portico_protocol::{Granularity, LookaheadCull, Policy, RangeCull};

/// Applies a policy spec on top of `base`; unknown keys or values are errors naming them.
pub fn parse_policy(spec: &str, base: Policy) -> Result<Policy, String> {
    let mut p = base;
    for part in spec.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (k, v) = part
            .split_once('=')
            .ok_or_else(|| format!("policy item {part:?} is not key=value"))?;
        let bad = || format!("policy {k}={v:?} is not valid");
        match k {
            "depth" => p.depth_frames = v.parse().map_err(|_| bad())?,
            "gran" | "granularity" => {
                p.granularity = match v {
                    "object" => Granularity::Object,
                    "cell" => Granularity::Cell,
                    _ => return Err(bad()),
                }
            }
            "range" => {
                p.range_cull = match v {
                    "any" => RangeCull::Any,
                    "plane" => RangeCull::Plane,
                    "frustum" => RangeCull::Frustum,
                    "direction" => RangeCull::Direction,
                    _ => return Err(bad()),
                }
            }
            "look" | "lookahead" => {
                p.lookahead_cull = match v {
                    "any" => LookaheadCull::Any,
                    "plane" => LookaheadCull::Plane,
                    "frustum" => LookaheadCull::Frustum,
                    "predicted" => LookaheadCull::Predicted,
                    _ => return Err(bad()),
                }
            }
            "read" => p.read_bytes = parse_bytes(v).ok_or_else(bad)?,
            "size" => p.size_threshold_px = v.parse().map_err(|_| bad())?,
            "imp" | "impostors" => {
                p.impostors = match v {
                    "1" | "yes" | "true" => true,
                    "0" | "no" | "false" => false,
                    _ => return Err(bad()),
                }
            }
            "bc" | "block" => {
                p.block_textures = match v {
                    "1" | "yes" | "true" => true,
                    "0" | "no" | "false" => false,
                    _ => return Err(bad()),
                }
            }
            _ => {
                return Err(format!(
                    "unknown policy key {k:?} (depth, gran, range, look, read, size, imp, bc)"
                ));
            }
        }
    }
    Ok(p)
}

/// `1024`, `64k`, `4m`, `1g` → bytes.
pub fn parse_bytes(v: &str) -> Option<u64> {
    let v = v.trim().to_ascii_lowercase();
    let (num, mult) = match v.chars().last()? {
        'k' => (&v[..v.len() - 1], 1u64 << 10),
        'm' => (&v[..v.len() - 1], 1 << 20),
        'g' => (&v[..v.len() - 1], 1 << 30),
        _ => (v.as_str(), 1),
    };
    num.parse::<u64>().ok()?.checked_mul(mult)
}

/// The spec string of a policy (inverse of [`parse_policy`] for the keys it names).
pub fn policy_spec(p: &Policy) -> String {
    let s = serde_json::to_value(p).unwrap_or_default();
    let name = |k: &str| s[k].as_str().unwrap_or("?").to_string();
    format!(
        "depth={},gran={},range={},look={}{}{}",
        p.depth_frames,
        name("granularity"),
        name("range_cull"),
        name("lookahead_cull"),
        if p.impostors { ",imp=1" } else { "" },
        if p.block_textures { ",bc=1" } else { "" }
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_and_print_back() {
        let p = parse_policy(
            "depth=32,gran=cell,range=frustum,look=plane,read=2m",
            Policy::default(),
        )
        .unwrap();
        assert_eq!(p.depth_frames, 32);
        assert_eq!(p.granularity, Granularity::Cell);
        assert_eq!(p.range_cull, RangeCull::Frustum);
        assert_eq!(p.lookahead_cull, LookaheadCull::Plane);
        assert_eq!(p.read_bytes, 2 << 20);
        assert_eq!(
            policy_spec(&p),
            "depth=32,gran=cell,range=frustum,look=plane"
        );
        let bc = parse_policy("bc=1", Policy::default()).unwrap();
        assert!(bc.block_textures);
        assert_eq!(
            policy_spec(&bc),
            "depth=16,gran=object,range=direction,look=predicted,bc=1"
        );
        assert!(
            parse_policy("depth=x", Policy::default())
                .unwrap_err()
                .contains("depth")
        );
        assert!(
            parse_policy("colour=red", Policy::default())
                .unwrap_err()
                .contains("unknown")
        );
        assert!(parse_policy("depth", Policy::default()).is_err());
        assert_eq!(parse_bytes("64k"), Some(65536));
        assert_eq!(parse_bytes("99999999999999999g"), None);
    }
}
