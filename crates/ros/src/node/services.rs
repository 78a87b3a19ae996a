//! The node's services, answered from the latest map snapshot on their own
//! thread: `get_distances`, `get_esdf_box`, `save_map`.

use super::types::{GetDistancesRequest, GetDistancesResponse, GetEsdfBoxRequest, GetEsdfBoxResponse, Point, SaveMapRequest, SaveMapResponse, Time, Vector3};
use super::live::Skipped;
use super::rpc::Server;
use super::{NodeError, Shared, Snapshot};
use edtmap::cpu::query;
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::dds::rustdds::{DomainParticipant, QosPolicies};
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::QosProfile;
use serde::de::DeserializeOwned;
use serde::Serialize;
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

/// Services' QoS, as ROS 2's default for services: reliable, volatile,
/// keep last 10.
fn qos() -> QosPolicies {
    QosPolicies::from(QosProfile::publisher_default().reliability_reliable(WhenFull::Wait(Duration::from_millis(100))).durability(Durability::Volatile).history(History::KeepLast { depth: 10 }))
}

/// The server `NAMESPACE/edtmap/BASE` of `edtmap_msgs/srv/TY`.
fn server<Req: DeserializeOwned, Resp: Serialize>(dp: &DomainParticipant, namespace: &str, base: &str, ty: &str) -> Result<Server<Req, Resp>, NodeError> {
    let name = super::own_name(namespace, base)?.to_string();
    let service = if name.starts_with('/') { name } else { format!("/{name}") };
    Server::create(dp, &service, "edtmap_msgs", ty, &qos()).map_err(|e| NodeError::Dds(format!("service edtmap/{base}: {e}")))
}

impl Servers {
    /// Creates the servers under `NAMESPACE/edtmap/`, answering clients of
    /// either RMW layout ([`super::rpc`]).
    pub(super) fn create(dp: &DomainParticipant, namespace: &str) -> Result<Self, NodeError> {
        Ok(Servers { distances: server(dp, namespace, "get_distances", "GetDistances")?, esdf_box: server(dp, namespace, "get_esdf_box", "GetEsdfBox")?, save: server(dp, namespace, "save_map", "SaveMap")? })
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
        answer_all(&self.distances, "get_distances", shared, |req| distances(&shared.snapshot(), req));
        answer_all(&self.esdf_box, "get_esdf_box", shared, |req| esdf_box(&shared.snapshot(), req));
        answer_all(&self.save, "save_map", shared, |req| save(&shared.snapshot(), req));
    }
}

/// Answers every request waiting on `server`; one that cannot be decoded
/// (no reply can be addressed) or answered is counted by kind and logged
/// the first time.
fn answer_all<Req: DeserializeOwned, Resp: Serialize>(server: &Server<Req, Resp>, service: &str, shared: &Shared, f: impl Fn(&Req) -> Resp) {
    while let Some(request) = server.receive() {
        let (id, req) = match request {
            Ok(r) => r,
            Err(e) => {
                shared.skip(&Skipped { kind: "bad request", reason: format!("{service}: a request that decodes in no RMW's layout: {e}") });
                continue;
            }
        };
        let resp = f(&req);
        shared.requests.fetch_add(1, Relaxed);
        if let Err(e) = server.reply(id, &resp) {
            shared.skip(&Skipped { kind: "reply not sent", reason: format!("{service}: {e}") });
        }
    }
}

/// `save_map`: the snapshot's map written atomically to the path asked.
fn save(snap: &Snapshot, req: &SaveMapRequest) -> SaveMapResponse {
    match req.path.trim() {
        "" => SaveMapResponse { success: false, message: "path is empty: give the file to write".into() },
        path => match edtmap::save_map(&snap.map, std::path::Path::new(path)) {
            Ok(()) => SaveMapResponse { success: true, message: format!("saved the map after {} frames to {path}", snap.frames) },
            Err(e) => SaveMapResponse { success: false, message: e.to_string() },
        },
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
    let answers = query::distances(&snap.map, &points, req.signed_distance);
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
    match query::distance_box(&snap.map, xyz(&req.min_corner), xyz(&req.max_corner), req.signed_distance) {
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
