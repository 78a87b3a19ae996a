//! The node's services, answered from the latest map snapshot on their own
//! thread: `get_distances`, `get_esdf_box`, `save_map`.

use super::live::Skipped;
use super::rpc::Server;
use super::rpc::{Refused, Request};
use super::types::{
    GetDistancesRequest, GetDistancesResponse, GetEsdfBoxRequest, GetEsdfBoxResponse, Point, SaveMapRequest,
    SaveMapResponse, Time, Vector3,
};
use super::{NodeError, Shared, Snapshot};
use edtmap::query;
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::dds::rustdds::{DomainParticipant, QosPolicies};
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::QosProfile;
use serde::Serialize;
use std::sync::atomic::Ordering::Relaxed;
use std::time::Duration;

/// Most points one `get_distances` call is answered for; more are refused.
pub const MAX_QUERY_POINTS: usize = 1_000_000;
/// Most voxels one `get_esdf_box` box may hold; more are refused.
pub const MAX_BOX_VOXELS: usize = 8_000_000;
/// Bytes one query point holds while it is answered: the request as it
/// came and decoded (2 × 24), the point (24), its answer (40), the reply's
/// arrays and their encoding (2 × 34), rounded up.
const BYTES_PER_QUERY_POINT: u64 = 192;
/// Bytes one box voxel holds while it is answered: distance, state and
/// gradient (4 + 1 + 12), and their encoding again.
const BYTES_PER_BOX_VOXEL: u64 = 34;
/// One request may use at most this fraction (1/N) of the memory budget.
const REQUEST_BUDGET_SHARE: u64 = 4;
/// Largest `get_esdf_box` or `save_map` request, bytes (a box is 49 bytes,
/// a path a few hundred).
const SMALL_REQUEST_BYTES: usize = 64 * 1024;

/// How much one request may ask for: [`MAX_QUERY_POINTS`] and
/// [`MAX_BOX_VOXELS`], lowered so that one request needs at most a quarter
/// of the memory budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct QueryLimits {
    /// Most points per `get_distances` call.
    pub points: usize,
    /// Most voxels per `get_esdf_box` box.
    pub box_voxels: usize,
}

impl QueryLimits {
    /// The limits under a memory budget of `budget_bytes` (none: the fixed caps).
    pub fn of_budget(budget_bytes: Option<u64>) -> Self {
        let fit = |per: u64, cap: usize| {
            budget_bytes
                .map_or(cap, |b| usize::try_from(b / REQUEST_BUDGET_SHARE / per).unwrap_or(usize::MAX).clamp(1, cap))
        };
        QueryLimits {
            points: fit(BYTES_PER_QUERY_POINT, MAX_QUERY_POINTS),
            box_voxels: fit(BYTES_PER_BOX_VOXEL, MAX_BOX_VOXELS),
        }
    }

    /// Largest `get_distances` payload, bytes: the points at 24 bytes, a
    /// Cyclone header, the length, the flag and padding.
    fn distances_request_bytes(&self) -> usize {
        self.points.saturating_mul(24).saturating_add(64)
    }
}

impl Request for GetDistancesRequest {
    /// `geometry_msgs/Point[] points`: three float64 each.
    const LEADING_ELEMENT_BYTES: usize = 24;
}

impl Request for GetEsdfBoxRequest {}

impl Request for SaveMapRequest {
    /// `string path`: a byte per character.
    const LEADING_ELEMENT_BYTES: usize = 1;
}

/// The three servers.
pub(super) struct Servers {
    distances: Server<GetDistancesRequest, GetDistancesResponse>,
    esdf_box: Server<GetEsdfBoxRequest, GetEsdfBoxResponse>,
    save: Server<SaveMapRequest, SaveMapResponse>,
    limits: QueryLimits,
}

/// Services' QoS, as ROS 2's default for services: reliable, volatile,
/// keep last 10.
fn qos() -> QosPolicies {
    QosPolicies::from(
        QosProfile::publisher_default()
            .reliability_reliable(WhenFull::Wait(Duration::from_millis(100)))
            .durability(Durability::Volatile)
            .history(History::KeepLast { depth: 10 }),
    )
}

/// The server `NAMESPACE/edtmap/BASE` of `edtmap_msgs/srv/TY`.
fn server<Req: Request, Resp: Serialize>(
    dp: &DomainParticipant,
    namespace: &str,
    base: &str,
    ty: &str,
    max_request_bytes: usize,
) -> Result<Server<Req, Resp>, NodeError> {
    let name = super::own_name(namespace, base)?.to_string();
    let service = if name.starts_with('/') { name } else { format!("/{name}") };
    Server::create(dp, &service, "edtmap_msgs", ty, &qos(), max_request_bytes)
        .map_err(|e| NodeError::Dds(format!("service edtmap/{base}: {e}")))
}

impl Servers {
    /// Creates the servers under `NAMESPACE/edtmap/`, answering clients of
    /// either RMW layout ([`super::rpc`]), asked for at most `limits`.
    pub(super) fn create(dp: &DomainParticipant, namespace: &str, limits: QueryLimits) -> Result<Self, NodeError> {
        Ok(Servers {
            distances: server(dp, namespace, "get_distances", "GetDistances", limits.distances_request_bytes())?,
            esdf_box: server(dp, namespace, "get_esdf_box", "GetEsdfBox", SMALL_REQUEST_BYTES)?,
            save: server(dp, namespace, "save_map", "SaveMap", SMALL_REQUEST_BYTES)?,
            limits,
        })
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
        let limits = self.limits;
        let refused = |kind: &'static str, message: &str| shared.skip(&Skipped { kind, reason: message.to_string() });
        answer_all(
            &self.distances,
            "get_distances",
            shared,
            |req| {
                let resp = distances(&shared.snapshot(), req, &limits);
                if !resp.success {
                    refused("refused: get_distances over the point limit", &resp.message);
                }
                resp
            },
            |message| GetDistancesResponse { success: false, message, ..Default::default() },
        );
        answer_all(
            &self.esdf_box,
            "get_esdf_box",
            shared,
            |req| {
                let snap = shared.snapshot();
                if let Some(message) = over_box_limit(&snap, req, &limits) {
                    refused("refused: get_esdf_box over the voxel limit", &message);
                }
                esdf_box(&snap, req, &limits)
            },
            |message| GetEsdfBoxResponse { success: false, message, ..Default::default() },
        );
        answer_all(
            &self.save,
            "save_map",
            shared,
            |req| save(&shared.snapshot(), req),
            |message| SaveMapResponse { success: false, message },
        );
    }
}

/// Answers every request waiting on `server`; one that cannot be decoded
/// (no reply can be addressed) or answered is counted by kind and logged
/// the first time; one larger than the server takes is answered
/// `refuse(why)` undecoded.
fn answer_all<Req: Request, Resp: Serialize>(
    server: &Server<Req, Resp>,
    service: &str,
    shared: &Shared,
    f: impl Fn(&Req) -> Resp,
    refuse: impl Fn(String) -> Resp,
) {
    while let Some(request) = server.receive() {
        let (id, resp) = match request {
            Ok((id, req)) => (id, f(&req)),
            Err(Refused::Undecodable(e)) => {
                shared.skip(&Skipped {
                    kind: "bad request",
                    reason: format!("{service}: a request that decodes in no RMW's layout: {e}"),
                });
                continue;
            }
            Err(Refused::TooLarge { id, bytes, max_bytes }) => {
                let why = format!("{service}: a request of {bytes} bytes, over the {max_bytes} bytes this node takes (the per-call limit): split it");
                shared.skip(&Skipped { kind: "refused: request too large", reason: why.clone() });
                (id, refuse(why))
            }
        };
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
            Ok(()) => SaveMapResponse {
                success: true,
                message: format!("saved the map after {} frames to {path}", snap.frames),
            },
            Err(e) => SaveMapResponse { success: false, message: e.to_string() },
        },
    }
}

fn xyz(p: &Point) -> [f64; 3] {
    [p.x, p.y, p.z]
}

/// `get_distances`: distance, gradient, state and saturation per point,
/// as `Mapper::distances` gives them; more than `limits.points` points
/// are refused.
pub(super) fn distances(snap: &Snapshot, req: &GetDistancesRequest, limits: &QueryLimits) -> GetDistancesResponse {
    let stamp = Time::from_ns(snap.stamp_ns);
    if req.points.len() > limits.points {
        let message = format!("{} points asked; at most {} are answered per call (the point limit, from the memory budget): split the request", req.points.len(), limits.points);
        return GetDistancesResponse { success: false, message, map_stamp: stamp, ..Default::default() };
    }
    let points: Vec<[f64; 3]> = req.points.iter().map(xyz).collect();
    let answers = query::distances(&snap.map, &points, req.signed_distance);
    GetDistancesResponse {
        success: true,
        message: String::new(),
        map_stamp: stamp,
        distances: answers.iter().map(|a| a.distance_m).collect(),
        gradients: answers.iter().map(|a| Vector3 { x: a.gradient[0], y: a.gradient[1], z: a.gradient[2] }).collect(),
        states: answers.iter().map(|a| a.state as u8).collect(),
        saturated: answers.iter().map(|a| a.saturated).collect(),
    }
}

/// Voxels overlapping the box `[lo, hi)` at `vs` (as `query::distance_box`
/// counts them; infinite or NaN corners give NaN).
fn box_voxels(lo: [f64; 3], hi: [f64; 3], vs: f64) -> f64 {
    (0..3).map(|a| ((hi[a] / vs).ceil() - (lo[a] / vs).floor()).max(0.0)).product()
}

/// `get_esdf_box`: the dense distances of a box, with central-difference
/// gradients; a box of more than `limits.box_voxels` voxels is refused
/// before anything is allocated.
pub(super) fn esdf_box(snap: &Snapshot, req: &GetEsdfBoxRequest, limits: &QueryLimits) -> GetEsdfBoxResponse {
    let stamp = Time::from_ns(snap.stamp_ns);
    let vs = snap.map.voxel_size_m();
    if let Some(message) = over_box_limit(snap, req, limits) {
        return GetEsdfBoxResponse { success: false, message, map_stamp: stamp, voxel_size: vs, ..Default::default() };
    }
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
        Err(e) => GetEsdfBoxResponse {
            success: false,
            message: e.to_string(),
            map_stamp: stamp,
            voxel_size: vs,
            ..Default::default()
        },
    }
}

/// Why the box of `req` is refused unanswered, if it holds more voxels than
/// [`QueryLimits::box_voxels`].
fn over_box_limit(snap: &Snapshot, req: &GetEsdfBoxRequest, limits: &QueryLimits) -> Option<String> {
    let voxels = box_voxels(xyz(&req.min_corner), xyz(&req.max_corner), snap.map.voxel_size_m());
    (voxels > limits.box_voxels as f64).then(|| {
        format!(
            "a box of {voxels:.0} voxels; at most {} are answered per call (the voxel limit, from the memory budget): ask for smaller boxes",
            limits.box_voxels
        )
    })
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

    fn snapshot() -> Snapshot {
        let sensor = edtmap::sensor::Sensor::Points(edtmap::sensor::RangeLimits { min_m: 0.1, max_m: 20.0 });
        let mapper = edtmap::Mapper::new(sensor, edtmap::MapperParams::for_voxel_size(0.1)).expect("mapper");
        Snapshot { map: mapper.map().clone(), volume: None, stamp_ns: 7, frames: 0 }
    }

    #[test]
    fn requests_over_the_limits_are_refused_with_a_reason() {
        let limits = QueryLimits::of_budget(None);
        assert_eq!(limits, QueryLimits { points: MAX_QUERY_POINTS, box_voxels: MAX_BOX_VOXELS });
        // A smaller budget lowers both: 64 MB allows 16 MB per request.
        let small = QueryLimits::of_budget(Some(64 << 20));
        assert_eq!(small, QueryLimits { points: (16 << 20) / 192, box_voxels: (16 << 20) / 34 });
        let snap = snapshot();
        let few = QueryLimits { points: 3, box_voxels: 1000 };
        let ok =
            distances(&snap, &GetDistancesRequest { points: vec![Point::default(); 3], signed_distance: false }, &few);
        assert!(ok.success && ok.distances.len() == 3, "{}", ok.message);
        let over =
            distances(&snap, &GetDistancesRequest { points: vec![Point::default(); 4], signed_distance: false }, &few);
        assert!(!over.success && over.distances.is_empty() && over.message.contains("at most 3"), "{}", over.message);
        assert_eq!(over.map_stamp, Time::from_ns(7));
        let vs = snap.map.voxel_size_m();
        let corner = |v: f64| Point { x: v * vs, y: v * vs, z: v * vs };
        let fits = esdf_box(
            &snap,
            &GetEsdfBoxRequest { min_corner: corner(0.0), max_corner: corner(10.0), signed_distance: false },
            &few,
        );
        assert!(fits.success && fits.distances.len() == 1000, "{}", fits.message);
        let big = esdf_box(
            &snap,
            &GetEsdfBoxRequest { min_corner: corner(0.0), max_corner: corner(10.5), signed_distance: false },
            &few,
        );
        assert!(!big.success && big.distances.is_empty() && big.message.contains("1331 voxels"), "{}", big.message);
        // A box the size of the world is refused before anything is allocated.
        let world = esdf_box(
            &snap,
            &GetEsdfBoxRequest { min_corner: corner(-1e9), max_corner: corner(1e9), signed_distance: false },
            &limits,
        );
        assert!(!world.success && world.message.contains("voxel limit"), "{}", world.message);
        // Corners that are no box still get the query's own reason.
        let nan = esdf_box(
            &snap,
            &GetEsdfBoxRequest { min_corner: Point { x: f64::NAN, ..Point::default() }, ..Default::default() },
            &limits,
        );
        assert!(!nan.success && nan.message.contains("finite"), "{}", nan.message);
    }

    #[test]
    fn box_gradients_are_exact_on_a_linear_field() {
        let dims = [4, 3, 2];
        let vs = 0.5;
        let d: Vec<f32> = (0..24)
            .map(|i| {
                let (x, y, z) = (i % 4, (i / 4) % 3, i / 12);
                0.5 * x as f32 * vs - 2.0 * y as f32 * vs + 3.0 * z as f32 * vs
            })
            .collect();
        let g = box_gradients(&d, dims, vs);
        for v in g.chunks(3) {
            assert!((v[0] - 0.5).abs() < 1e-5 && (v[1] + 2.0).abs() < 1e-5 && (v[2] - 3.0).abs() < 1e-5, "{v:?}");
        }
        assert_eq!(box_gradients(&[1.0, 2.0], [2, 1, 1], 1.0), vec![1.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
    }
}
