//! The node's services, answered from the latest map snapshot on their own
//! thread: `get_distances`, `get_esdf_box`, `save_map`.

use super::types::{GetDistancesRequest, GetDistancesResponse, GetEsdfBoxRequest, GetEsdfBoxResponse, Point, SaveMapRequest, SaveMapResponse, Time, Vector3};
use super::{NodeError, Shared, Snapshot};
use edtmap::config::ServiceMapping;
use edtmap::cpu::query;
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{Node, QosProfile, Server, ServiceTypeName};
use std::sync::atomic::Ordering::Relaxed;
use std::time::Duration;

/// Most points one `get_distances` request may ask for.
pub(super) const MAX_QUERY_POINTS: usize = 10_000_000;

/// The three servers.
pub(super) struct Servers {
    distances: Server<GetDistancesRequest, GetDistancesResponse>,
    esdf_box: Server<GetEsdfBoxRequest, GetEsdfBoxResponse>,
    save: Server<SaveMapRequest, SaveMapResponse>,
}

fn qos() -> QosProfile {
    QosProfile::publisher_default().reliability_reliable(WhenFull::Wait(Duration::from_millis(100))).durability(Durability::Volatile).history(History::KeepLast { depth: 10 })
}

impl Servers {
    /// Creates the servers under `NAMESPACE/edtmap/`.
    pub(super) fn create(node: &mut Node, namespace: &str, mapping: ServiceMapping) -> Result<Self, NodeError> {
        let mapping = match mapping {
            ServiceMapping::Cyclone => ros2_client::ServiceMapping::Cyclone,
            ServiceMapping::Enhanced => ros2_client::ServiceMapping::Enhanced,
        };
        macro_rules! server {
            ($base:expr, $ty:expr) => {{
                let name = super::own_name(namespace, $base)?;
                node.create_server(mapping, &name, &ServiceTypeName::new("edtmap_msgs", $ty), qos(), qos()).map_err(|e| NodeError::Dds(format!("service edtmap/{}: {e:?}", $base)))?
            }};
        }
        Ok(Servers { distances: server!("get_distances", "GetDistances"), esdf_box: server!("get_esdf_box", "GetEsdfBox"), save: server!("save_map", "SaveMap") })
    }

    /// Answers requests until the node stops.
    pub(super) fn serve(mut self, shared: &Shared) {
        let poll = Poll::new().ok();
        let mut registered = false;
        if let Some(p) = &poll {
            let reg = p.registry();
            registered = reg.register(&mut self.distances, Token(0), Interest::READABLE).is_ok()
                && reg.register(&mut self.esdf_box, Token(1), Interest::READABLE).is_ok()
                && reg.register(&mut self.save, Token(2), Interest::READABLE).is_ok();
        }
        let mut poll = poll.filter(|_| registered);
        let mut events = Events::with_capacity(8);
        while !shared.stop.load(Relaxed) {
            match &mut poll {
                Some(p) => {
                    let _ = p.poll(&mut events, Some(Duration::from_millis(20)));
                }
                None => std::thread::sleep(Duration::from_millis(2)),
            }
            self.answer(shared);
        }
    }

    fn answer(&self, shared: &Shared) {
        while let Ok(Some((id, req))) = self.distances.receive_request() {
            let resp = distances(&shared.snapshot(), &req);
            shared.requests.fetch_add(1, Relaxed);
            if let Err(e) = self.distances.send_response(id, resp) {
                tracing::warn!("get_distances: the answer could not be sent: {e:?}");
            }
        }
        while let Ok(Some((id, req))) = self.esdf_box.receive_request() {
            let resp = esdf_box(&shared.snapshot(), &req);
            shared.requests.fetch_add(1, Relaxed);
            if let Err(e) = self.esdf_box.send_response(id, resp) {
                tracing::warn!("get_esdf_box: the answer could not be sent: {e:?}");
            }
        }
        while let Ok(Some((id, req))) = self.save.receive_request() {
            let snap = shared.snapshot();
            let resp = match req.path.trim() {
                "" => SaveMapResponse { success: false, message: "path is empty: give the file to write".into() },
                path => match edtmap::save_map(&snap.map, std::path::Path::new(path)) {
                    Ok(()) => SaveMapResponse { success: true, message: format!("saved the map after {} frames to {path}", snap.frames) },
                    Err(e) => SaveMapResponse { success: false, message: e.to_string() },
                },
            };
            shared.requests.fetch_add(1, Relaxed);
            if let Err(e) = self.save.send_response(id, resp) {
                tracing::warn!("save_map: the answer could not be sent: {e:?}");
            }
        }
    }
}

fn xyz(p: &Point) -> [f64; 3] {
    [p.x, p.y, p.z]
}

/// `get_distances`: distance, gradient, state and saturation per point,
/// as `Mapper::distances` gives them.
pub(super) fn distances(snap: &Snapshot, req: &GetDistancesRequest) -> GetDistancesResponse {
    let stamp = Time::from_ns(snap.stamp_ns);
    if req.points.len() > MAX_QUERY_POINTS {
        tracing::warn!("get_distances: {} points asked, at most {MAX_QUERY_POINTS} answered", req.points.len());
    }
    let points: Vec<[f64; 3]> = req.points.iter().take(MAX_QUERY_POINTS).map(xyz).collect();
    let answers = query::distances(&snap.map, &points, req.signed);
    GetDistancesResponse {
        map_stamp: stamp,
        distances: answers.iter().map(|a| a.distance_m).collect(),
        gradients: answers.iter().map(|a| Vector3 { x: a.gradient[0], y: a.gradient[1], z: a.gradient[2] }).collect(),
        states: answers.iter().map(|a| a.state as u8).collect(),
        saturated: answers.iter().map(|a| a.saturated).collect(),
    }
}

/// `get_esdf_box`: the dense distances of a box, with central-difference
/// gradients.
pub(super) fn esdf_box(snap: &Snapshot, req: &GetEsdfBoxRequest) -> GetEsdfBoxResponse {
    let stamp = Time::from_ns(snap.stamp_ns);
    let vs = snap.map.voxel_size_m();
    match query::distance_box(&snap.map, xyz(&req.min_corner), xyz(&req.max_corner), req.signed) {
        Ok(b) => {
            let origin = b.origin.centre(vs);
            let gradients = box_gradients(&b.distance_m, b.dims, vs as f32);
            GetEsdfBoxResponse {
                success: true,
                message: String::new(),
                map_stamp: stamp,
                origin: Point { x: origin[0], y: origin[1], z: origin[2] },
                voxel_size: vs,
                size: b.dims.map(|d| d as u32),
                distances: b.distance_m,
                gradients,
                states: b.state,
            }
        }
        Err(e) => GetEsdfBoxResponse { success: false, message: e.to_string(), map_stamp: stamp, voxel_size: vs, ..Default::default() },
    }
}

/// Central differences inside the box, one-sided on its faces (zero along
/// an axis one voxel thick); x, y, z interleaved per voxel.
fn box_gradients(d: &[f32], [nx, ny, nz]: [usize; 3], vs: f32) -> Vec<f32> {
    let at = |x: usize, y: usize, z: usize| d[x + nx * (y + ny * z)];
    let mut out = Vec::with_capacity(d.len() * 3);
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let c = [x, y, z];
                let n = [nx, ny, nz];
                for a in 0..3 {
                    let (lo, hi) = (c[a].saturating_sub(1), (c[a] + 1).min(n[a] - 1));
                    let g = if hi == lo {
                        0.0
                    } else {
                        let mut l = c;
                        let mut h = c;
                        l[a] = lo;
                        h[a] = hi;
                        (at(h[0], h[1], h[2]) - at(l[0], l[1], l[2])) / ((hi - lo) as f32 * vs)
                    };
                    out.push(g);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_gradients_are_exact_on_a_linear_field() {
        let dims = [4, 3, 2];
        let vs = 0.5;
        let d: Vec<f32> = (0..24).map(|i| {
            let (x, y, z) = (i % 4, (i / 4) % 3, i / 12);
            0.5 * x as f32 * vs - 2.0 * y as f32 * vs + 3.0 * z as f32 * vs
        }).collect();
        let g = box_gradients(&d, dims, vs);
        for v in g.chunks(3) {
            assert!((v[0] - 0.5).abs() < 1e-5 && (v[1] + 2.0).abs() < 1e-5 && (v[2] - 3.0).abs() < 1e-5, "{v:?}");
        }
        assert_eq!(box_gradients(&[1.0, 2.0], [2, 1, 1], 1.0), vec![1.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
    }
}
