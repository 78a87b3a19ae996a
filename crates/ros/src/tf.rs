//! A transform tree from `/tf` and `/tf_static`: the pose of one frame in
//! another at any time, through any chain of frames.
//!
//! Each edge `parent → child` keeps its own [`Trajectory`]; a lookup walks
//! the tree from the target frame to the source frame (edges may be taken
//! against their direction) and interpolates every moving edge at the asked
//! time. Static edges hold at all times.

use super::msg::StampedTransform;
use edtmap_io::trajectory::Trajectory;
use nalgebra::Isometry3;
use std::collections::{HashMap, VecDeque};

/// An edge of the tree: `(parent, child)` frame names.
type Edge = (String, String);

/// Transforms between named frames over time.
#[derive(Debug, Clone, Default)]
pub struct TfBuffer {
    moving: HashMap<Edge, Trajectory>,
    fixed: HashMap<Edge, Isometry3<f64>>,
}

/// ROS 1 frame ids may start with `/`; ROS 2's never do.
fn frame_name(id: &str) -> String {
    id.trim_start_matches('/').to_string()
}

impl TfBuffer {
    /// The tree of `(transform, is_static)` pairs: `is_static` for
    /// `/tf_static`, whose transforms hold at all times.
    pub fn new<'a>(transforms: impl IntoIterator<Item = (&'a StampedTransform, bool)>) -> Self {
        let mut moving: HashMap<Edge, Vec<(f64, Isometry3<f64>)>> = HashMap::new();
        let mut fixed = HashMap::new();
        for (t, is_static) in transforms {
            let key = (frame_name(&t.header.frame_id), frame_name(&t.child_frame));
            if is_static {
                fixed.insert(key, t.transform);
            } else {
                moving.entry(key).or_default().push((t.header.stamp_s(), t.transform));
            }
        }
        let moving = moving.into_iter().map(|(k, v)| (k, Trajectory::new(v))).collect();
        TfBuffer { moving, fixed }
    }

    /// Adds one transform as it arrives (`is_static` for `/tf_static`).
    pub fn insert(&mut self, t: &StampedTransform, is_static: bool) {
        let key = (frame_name(&t.header.frame_id), frame_name(&t.child_frame));
        if is_static {
            self.fixed.insert(key, t.transform);
        } else {
            self.moving.entry(key).or_default().push(t.header.stamp_s(), t.transform);
        }
    }

    /// Drops moving samples older than `t` (keeping one before it on every
    /// edge), to bound a live buffer's history.
    pub fn forget_before(&mut self, t: f64) {
        for traj in self.moving.values_mut() {
            traj.forget_before(t);
        }
    }

    /// The latest time every moving edge of the chain from `target` to
    /// `source` has a sample at; `None` when there is no chain. Static
    /// chains hold at every time (`f64::INFINITY`).
    pub fn latest_common(&self, target: &str, source: &str) -> Option<f64> {
        let (target, source) = (frame_name(target), frame_name(source));
        if target == source {
            return Some(f64::INFINITY);
        }
        let chain = self.path(&target, &source)?;
        Some(
            chain
                .iter()
                .filter_map(|(p, c, _)| self.moving.get(&(p.clone(), c.clone())))
                .filter_map(|t| t.span().map(|s| s.1))
                .fold(f64::INFINITY, f64::min),
        )
    }

    /// The root of the tree `frame` is in: the ancestor with no parent;
    /// `None` when no edge names `frame`.
    pub fn root_of(&self, frame: &str) -> Option<String> {
        let mut at = frame_name(frame);
        if !self.knows(&at) {
            return None;
        }
        for _ in 0..self.edges() {
            match self.moving.keys().chain(self.fixed.keys()).find(|(_, c)| *c == at) {
                Some((p, _)) => at = p.clone(),
                None => break,
            }
        }
        Some(at)
    }

    /// Whether an edge names `frame` (without a leading `/`).
    fn knows(&self, frame: &str) -> bool {
        self.moving.keys().chain(self.fixed.keys()).any(|(p, c)| p == frame || c == frame)
    }

    /// Number of moving samples held, all edges together.
    pub fn samples(&self) -> usize {
        self.moving.values().map(Trajectory::len).sum()
    }

    /// Number of edges.
    pub fn edges(&self) -> usize {
        self.moving.len() + self.fixed.len()
    }

    /// The chain of edges from `target` to `source`: `(parent, child,
    /// forward)` where `forward` means the edge points away from `target`.
    fn path(&self, target: &str, source: &str) -> Option<Vec<(String, String, bool)>> {
        let mut next: HashMap<&str, Vec<(&str, &str, bool)>> = HashMap::new();
        for (p, c) in self.moving.keys().chain(self.fixed.keys()) {
            next.entry(p.as_str()).or_default().push((p.as_str(), c.as_str(), true));
            next.entry(c.as_str()).or_default().push((p.as_str(), c.as_str(), false));
        }
        let mut came: HashMap<&str, (&str, &str, bool)> = HashMap::new();
        let mut queue = VecDeque::from([target]);
        while let Some(f) = queue.pop_front() {
            if f == source {
                let mut chain = Vec::new();
                let mut at = source;
                while at != target {
                    let (p, c, fwd) = came[at];
                    chain.push((p.to_string(), c.to_string(), fwd));
                    at = if fwd { p } else { c };
                }
                chain.reverse();
                return Some(chain);
            }
            for &(p, c, fwd) in next.get(f).map(Vec::as_slice).unwrap_or_default() {
                let other = if fwd { c } else { p };
                if other != target && !came.contains_key(other) {
                    came.insert(other, (p, c, fwd));
                    queue.push_back(other);
                }
            }
        }
        None
    }

    /// `T_target_source` at time `t` (seconds), moving edges interpolated
    /// between samples at most `max_gap_s` apart.
    pub fn lookup(&self, target: &str, source: &str, t: f64, max_gap_s: f64) -> Result<Isometry3<f64>, String> {
        let (target, source) = (frame_name(target), frame_name(source));
        if !self.knows(&source) {
            return Err(format!(
                "frame {source:?} is not in the transform tree (frames known: {})",
                self.frames().join(", ")
            ));
        }
        if target == source {
            return Ok(Isometry3::identity());
        }
        let chain = self.path(&target, &source).ok_or_else(|| {
            format!("no chain of transforms from {target} to {source} (frames known: {})", self.frames().join(", "))
        })?;
        let mut pose = Isometry3::identity();
        for (p, c, forward) in chain {
            let key = (p, c);
            let edge = match self.fixed.get(&key) {
                Some(fixed) => *fixed,
                None => match self.moving.get(&key) {
                    Some(traj) => {
                        traj.pose_at(t, max_gap_s).map_err(|e| format!("transform {} → {}: {e}", key.0, key.1))?
                    }
                    None => return Err(format!("no transform {} → {}", key.0, key.1)),
                },
            };
            pose *= if forward { edge } else { edge.inverse() };
        }
        Ok(pose)
    }

    /// Every frame named by an edge, sorted.
    pub fn frames(&self) -> Vec<String> {
        let mut names: Vec<String> =
            self.moving.keys().chain(self.fixed.keys()).flat_map(|(p, c)| [p.clone(), c.clone()]).collect();
        names.sort();
        names.dedup();
        names
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::Header;
    use nalgebra::Vector3;

    fn edge(parent: &str, child: &str, t: f64, x: f64, yaw: f64) -> StampedTransform {
        StampedTransform {
            header: Header { stamp_ns: (t * 1e9) as i64, frame_id: parent.into() },
            child_frame: child.into(),
            transform: Isometry3::new(Vector3::new(x, 0.0, 0.0), Vector3::new(0.0, 0.0, yaw)),
        }
    }

    #[test]
    fn composes_a_chain_with_static_and_inverted_edges() {
        // map → odom moves along x; odom → base_link turns; base_link → lidar is static.
        let edges = [
            (edge("/map", "odom", 0.0, 0.0, 0.0), false),
            (edge("map", "odom", 1.0, 2.0, 0.0), false),
            (edge("odom", "base_link", 0.0, 0.0, 0.0), false),
            (edge("odom", "base_link", 1.0, 0.0, 1.0), false),
            (edge("base_link", "lidar", 0.0, 0.5, 0.0), true),
        ];
        let tf = TfBuffer::new(edges.iter().map(|(e, s)| (e, *s)));
        assert_eq!(tf.root_of("/lidar").as_deref(), Some("map"));
        assert_eq!(tf.root_of("camera"), None);
        let got = tf.lookup("map", "lidar", 0.5, 1.0).expect("chain");
        // Expected by hand: x 1, yaw 0.5, then the lidar 0.5 m ahead along the turned x.
        let want = Isometry3::new(
            Vector3::new(1.0 + 0.5 * 0.5f64.cos(), 0.5 * 0.5f64.sin(), 0.0),
            Vector3::new(0.0, 0.0, 0.5),
        );
        assert!((got.to_homogeneous() - want.to_homogeneous()).abs().max() < 1e-12, "{got} vs {want}");
        let back = tf.lookup("lidar", "map", 0.5, 1.0).expect("inverse chain");
        assert!((back.to_homogeneous() - want.inverse().to_homogeneous()).abs().max() < 1e-12);
        assert!(tf.lookup("map", "lidar", 1.5, 1.0).expect_err("after").contains("odom"));
        assert!(tf.lookup("map", "camera", 0.5, 1.0).expect_err("unknown").contains("not in the transform tree"));
    }
}
