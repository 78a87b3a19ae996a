//! Service servers that answer both request layouts ROS 2's usual RMW
//! implementations put on DDS, told apart request by request, so a node
//! needs no setting to serve Fast DDS and Cyclone DDS clients alike.
//!
//! - `rmw_fastrtps_cpp` (the "enhanced" mapping of OMG RPC over DDS) sends
//!   the bare request; the id travels outside the payload, in the RTPS
//!   sample identity, with the client's reply reader in the inline QoS
//!   `related_sample_identity` (sequence number unknown). The reply carries
//!   `related_sample_identity` = that reader (or the request's writer) and
//!   the request's sequence number.
//! - `rmw_cyclonedds_cpp` prefixes the payload with a 16-byte header (a
//!   64-bit client id and a 64-bit sequence number) and no inline QoS; the
//!   reply starts with the same header.
//!
//! `ros2-client`'s `Server` fixes one layout per server, so the servers
//! here read the raw payload and pick the layout per request: a request
//! whose related identity has an unknown sequence number is Fast DDS's;
//! otherwise the header layout is tried first (it must account for the
//! whole payload), then the bare one.
//!
//! A request larger than its server takes is refused undecoded, so that
//! nothing is built from it: the reply goes to the Fast DDS identity when
//! one came with it, else to the Cyclone header in its first 16 bytes.
//! Decoding itself allocates only what the bytes hold: a sequence's
//! elements are read one by one from the payload, and its declared
//! length is checked against the bytes left before anything is reserved.

use ros2_client::dds::rustdds::bytes::Bytes;
use ros2_client::dds::rustdds::mio1;
use ros2_client::dds::rustdds::no_key::{self, DataWriter, SimpleDataReader};
use ros2_client::dds::rustdds::rpc::SampleIdentity;
use ros2_client::dds::rustdds::serialization::{deserialize_from_cdr_with_rep_id, to_writer_with_rep_id};
use ros2_client::dds::rustdds::{
    DomainParticipant, QosPolicies, QosPolicyBuilder, RepresentationIdentifier, SequenceNumber, Timestamp, TopicKind,
    WriteOptionsBuilder, GUID,
};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::marker::PhantomData;

/// A sample's payload as it came, with its CDR byte order.
pub(super) struct Raw {
    bytes: Bytes,
    encoding: RepresentationIdentifier,
}

/// Passes payloads through undecoded (decoding needs the layout, known
/// only per request).
pub(super) struct RawAdapter;

/// The adapters' error: never raised, as a payload is kept as it came.
#[derive(Debug, thiserror::Error)]
#[error("unreachable")]
pub(super) struct Never;

/// The decoder of [`RawAdapter`].
#[derive(Clone)]
pub(super) struct RawDecoder;

const ENCODINGS: [RepresentationIdentifier; 2] = [RepresentationIdentifier::CDR_LE, RepresentationIdentifier::CDR_BE];

impl no_key::DeserializerAdapter<Raw> for RawAdapter {
    type Error = Never;
    type Decoded = Raw;
    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &ENCODINGS
    }
    fn transform_decoded(decoded: Raw) -> Raw {
        decoded
    }
}

impl<'de> no_key::Decode<'de, Raw> for RawDecoder {
    type Error = Never;
    fn decode_bytes(self, input_bytes: &'de [u8], encoding: RepresentationIdentifier) -> Result<Raw, Never> {
        Ok(Raw { bytes: Bytes::copy_from_slice(input_bytes), encoding })
    }
}

impl no_key::DefaultDecoder<Raw> for RawAdapter {
    type Decoder = RawDecoder;
    const DECODER: RawDecoder = RawDecoder;
}

impl no_key::SerializerAdapter<Raw> for RawAdapter {
    type Error = Never;
    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }
    fn to_bytes(value: &Raw) -> Result<Bytes, Never> {
        Ok(value.bytes.clone())
    }
}

/// Which RMW's layout a request came in, and what its reply must carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum RequestId {
    /// Cyclone DDS: the header's client id and sequence number, echoed.
    Header { client: u64, seq: i64 },
    /// Fast DDS (and any bare request): the identity the reply relates to.
    Bare(SampleIdentity),
}

/// Why a request gets no answer from its service.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum Refused {
    /// It fits no layout: no reply can be addressed.
    Undecodable(String),
    /// It is larger than the server takes; refused undecoded, to `id`.
    TooLarge { id: RequestId, bytes: usize, max_bytes: usize },
}

/// Bytes a payload may hold past its data: CDR pads it to 4 bytes.
const MAX_PADDING: usize = 3;

/// A service request type. Its first field may be a sequence (or string),
/// whose declared length is checked against the payload before decoding.
pub(super) trait Request: DeserializeOwned {
    /// Bytes per element of the leading sequence on the wire (0: none).
    const LEADING_ELEMENT_BYTES: usize = 0;
}

/// Whether the sequence whose length is at byte `at` of `bytes` fits in
/// the bytes after it, at `element_bytes` per element.
fn declared_fits(
    bytes: &[u8],
    encoding: RepresentationIdentifier,
    at: usize,
    element_bytes: usize,
) -> Result<(), String> {
    if element_bytes == 0 {
        return Ok(());
    }
    let Some(&[a, b, c, d]) = bytes.get(at..at + 4) else { return Err("no sequence length".into()) };
    let n = if encoding == RepresentationIdentifier::CDR_BE {
        u32::from_be_bytes([a, b, c, d])
    } else {
        u32::from_le_bytes([a, b, c, d])
    };
    let left = bytes.len() - at - 4;
    match u64::from(n) * element_bytes as u64 {
        need if need <= left as u64 => Ok(()),
        need => Err(format!("a sequence of {n} elements ({need} bytes) in the {left} bytes left")),
    }
}

/// Decodes `T` from `bytes`, which it must fill but for padding, its
/// leading sequence (at `at`) checked first.
fn whole<T: DeserializeOwned>(
    bytes: &[u8],
    encoding: RepresentationIdentifier,
    at: usize,
    element_bytes: usize,
) -> Result<T, String> {
    declared_fits(bytes, encoding, at, element_bytes)?;
    let (value, used) = deserialize_from_cdr_with_rep_id::<T>(bytes, encoding).map_err(|e| e.to_string())?;
    match bytes.len() - used.min(bytes.len()) {
        extra if extra <= MAX_PADDING => Ok(value),
        extra => Err(format!("{extra} bytes past the request")),
    }
}

/// The request in `raw`, with its id, by the layout it fits (see the
/// module docs); `writer` and `sn` are the sample's own identity.
pub(super) fn decode<Req: Request>(
    raw: &Raw,
    related: Option<SampleIdentity>,
    writer: GUID,
    sn: SequenceNumber,
) -> Result<(RequestId, Req), String> {
    let bare_id = || {
        let writer_guid = related.map(|r| r.writer_guid).filter(|g| *g != GUID::GUID_UNKNOWN).unwrap_or(writer);
        RequestId::Bare(SampleIdentity { writer_guid, sequence_number: sn })
    };
    if related.is_some_and(|r| r.sequence_number == SequenceNumber::UNKNOWN) {
        return whole::<Req>(&raw.bytes, raw.encoding, 0, Req::LEADING_ELEMENT_BYTES)
            .map(|r| (bare_id(), r))
            .map_err(|e| format!("a Fast DDS request: {e}"));
    }
    let header = match whole::<(u64, i64, Req)>(&raw.bytes, raw.encoding, 16, Req::LEADING_ELEMENT_BYTES) {
        Ok((client, seq, req)) => return Ok((RequestId::Header { client, seq }, req)),
        Err(e) => e,
    };
    match whole::<Req>(&raw.bytes, raw.encoding, 0, Req::LEADING_ELEMENT_BYTES) {
        Ok(req) => Ok((bare_id(), req)),
        Err(bare) => Err(format!("neither a Cyclone DDS request ({header}) nor a bare one ({bare})")),
    }
}

/// The reply to `id`: its payload and the identity it relates to.
pub(super) fn encode<Resp: Serialize>(id: RequestId, resp: &Resp) -> Result<(Raw, Option<SampleIdentity>), String> {
    let mut out = Vec::new();
    let encoding = RepresentationIdentifier::CDR_LE;
    let related = match id {
        RequestId::Header { client, seq } => {
            to_writer_with_rep_id(&mut out, &(client, seq, resp), encoding).map_err(|e| e.to_string())?;
            None
        }
        RequestId::Bare(identity) => {
            to_writer_with_rep_id(&mut out, resp, encoding).map_err(|e| e.to_string())?;
            Some(identity)
        }
    };
    Ok((Raw { bytes: Bytes::from(out), encoding }, related))
}

/// One service's request reader and reply writer.
pub(super) struct Server<Req, Resp> {
    requests: SimpleDataReader<Raw, RawAdapter>,
    replies: DataWriter<Raw, RawAdapter>,
    max_request_bytes: usize,
    types: PhantomData<fn(Req) -> Resp>,
}

/// The id to refuse an undecoded request to: its Fast DDS identity, or
/// the Cyclone header of its first 16 bytes.
fn refusal_id(raw: &Raw, related: Option<SampleIdentity>, writer: GUID, sn: SequenceNumber) -> RequestId {
    let head = raw.bytes.get(..16).filter(|_| related.is_none());
    match head.and_then(|h| <[u8; 16]>::try_from(h).ok()) {
        Some(h) => {
            let le = raw.encoding != RepresentationIdentifier::CDR_BE;
            let (c, s) = (
                [h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7]],
                [h[8], h[9], h[10], h[11], h[12], h[13], h[14], h[15]],
            );
            if le {
                RequestId::Header { client: u64::from_le_bytes(c), seq: i64::from_le_bytes(s) }
            } else {
                RequestId::Header { client: u64::from_be_bytes(c), seq: i64::from_be_bytes(s) }
            }
        }
        None => {
            let writer_guid = related.map(|r| r.writer_guid).filter(|g| *g != GUID::GUID_UNKNOWN).unwrap_or(writer);
            RequestId::Bare(SampleIdentity { writer_guid, sequence_number: sn })
        }
    }
}

/// The request in `raw` as [`decode`] reads it, unless it is over
/// `max_bytes`.
pub(super) fn receive_one<Req: Request>(
    raw: &Raw,
    related: Option<SampleIdentity>,
    writer: GUID,
    sn: SequenceNumber,
    max_bytes: usize,
) -> Result<(RequestId, Req), Refused> {
    if raw.bytes.len() > max_bytes {
        return Err(Refused::TooLarge { id: refusal_id(raw, related, writer, sn), bytes: raw.bytes.len(), max_bytes });
    }
    decode(raw, related, writer, sn).map_err(Refused::Undecodable)
}

impl<Req: Request, Resp: Serialize> Server<Req, Resp> {
    /// The server of the DDS topics `rq{service}Request` and
    /// `rr{service}Reply` (`service` absolute, e.g. `/edtmap/save_map`),
    /// of the types `{package}::srv::dds_::{ty}_Request_` / `_Response_`,
    /// taking requests of at most `max_request_bytes`.
    pub(super) fn create(
        dp: &DomainParticipant,
        service: &str,
        package: &str,
        ty: &str,
        qos: &QosPolicies,
        max_request_bytes: usize,
    ) -> Result<Self, String> {
        let rq = dp
            .create_topic(
                format!("rq{service}Request"),
                format!("{package}::srv::dds_::{ty}_Request_"),
                qos,
                TopicKind::NoKey,
            )
            .map_err(|e| format!("{e:?}"))?;
        let rr = dp
            .create_topic(
                format!("rr{service}Reply"),
                format!("{package}::srv::dds_::{ty}_Response_"),
                qos,
                TopicKind::NoKey,
            )
            .map_err(|e| format!("{e:?}"))?;
        let none = QosPolicyBuilder::new().build();
        let requests = dp
            .create_subscriber(&none)
            .and_then(|s| s.create_simple_datareader_no_key::<Raw, RawAdapter>(&rq, Some(qos.clone())))
            .map_err(|e| format!("{e:?}"))?;
        let replies = dp
            .create_publisher(&none)
            .and_then(|p| p.create_datawriter_no_key::<Raw, RawAdapter>(&rr, Some(qos.clone())))
            .map_err(|e| format!("{e:?}"))?;
        Ok(Server { requests, replies, max_request_bytes, types: PhantomData })
    }

    /// The next request: `None` when none waits, `Some(Err)` for one that
    /// fits no layout or is too large.
    pub(super) fn receive(&self) -> Option<Result<(RequestId, Req), Refused>> {
        self.requests.drain_read_notifications();
        let sample = match self.requests.try_take_one() {
            Ok(Some(s)) => s,
            Ok(None) => return None,
            Err(e) => return Some(Err(Refused::Undecodable(format!("{e:?}")))),
        };
        let related = sample.related_sample_identity();
        Some(receive_one(&sample.sample, related, sample.writer_guid, sample.sequence_number, self.max_request_bytes))
    }

    /// Sends the reply to `id`.
    pub(super) fn reply(&self, id: RequestId, resp: &Resp) -> Result<(), String> {
        let (raw, related) = encode(id, resp)?;
        let mut options = WriteOptionsBuilder::new().source_timestamp(Timestamp::now());
        if let Some(r) = related {
            options = options.related_sample_identity(r);
        }
        self.replies.write_with_options(raw, options.build()).map(|_| ()).map_err(|e| format!("{:?}", e.forget_data()))
    }
}

impl<Req, Resp> mio1::event::Source for Server<Req, Resp> {
    fn register(
        &mut self,
        registry: &mio1::Registry,
        token: mio1::Token,
        interests: mio1::Interest,
    ) -> std::io::Result<()> {
        self.requests.register(registry, token, interests)
    }
    fn reregister(
        &mut self,
        registry: &mio1::Registry,
        token: mio1::Token,
        interests: mio1::Interest,
    ) -> std::io::Result<()> {
        self.requests.reregister(registry, token, interests)
    }
    fn deregister(&mut self, registry: &mio1::Registry) -> std::io::Result<()> {
        self.requests.deregister(registry)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::{GetDistancesRequest, Point, SaveMapRequest};

    fn raw<T: Serialize>(value: &T) -> Raw {
        let mut out = Vec::new();
        to_writer_with_rep_id(&mut out, value, RepresentationIdentifier::CDR_LE).expect("serialize");
        // As RTPS carries it: padded to 4 bytes.
        out.resize(out.len().div_ceil(4) * 4, 0);
        Raw { bytes: Bytes::from(out), encoding: RepresentationIdentifier::CDR_LE }
    }

    fn guid(b: u8) -> GUID {
        GUID::from_bytes([b; 16])
    }

    fn request() -> GetDistancesRequest {
        GetDistancesRequest {
            points: vec![Point { x: 1.0, y: -2.0, z: 0.5 }, Point { x: 3.0, y: 0.0, z: 0.0 }],
            signed_distance: true,
        }
    }

    #[test]
    fn a_fast_dds_request_is_answered_to_its_reply_reader_with_its_own_sequence_number() {
        let related = SampleIdentity { writer_guid: guid(7), sequence_number: SequenceNumber::UNKNOWN };
        let (id, req) =
            decode::<GetDistancesRequest>(&raw(&request()), Some(related), guid(3), SequenceNumber::from(12))
                .expect("decode");
        assert_eq!(req, request());
        assert_eq!(
            id,
            RequestId::Bare(SampleIdentity { writer_guid: guid(7), sequence_number: SequenceNumber::from(12) })
        );
    }

    #[test]
    fn a_cyclone_request_is_answered_with_its_header() {
        let (id, req) = decode::<GetDistancesRequest>(
            &raw(&(0xdead_beef_u64, 5_i64, request())),
            None,
            guid(3),
            SequenceNumber::from(1),
        )
        .expect("decode");
        assert_eq!((id, req), (RequestId::Header { client: 0xdead_beef, seq: 5 }, request()));
        let (reply, related) = encode(id, &SaveMapRequest { path: "x".into() }).expect("encode");
        assert_eq!(related, None);
        let (client, seq, back): (u64, i64, SaveMapRequest) =
            deserialize_from_cdr_with_rep_id(&reply.bytes, reply.encoding).expect("decode").0;
        assert_eq!((client, seq, back.path.as_str()), (0xdead_beef, 5, "x"));
    }

    #[test]
    fn a_bare_request_without_identity_is_answered_to_its_writer() {
        for req in [request(), GetDistancesRequest::default()] {
            let (id, got) =
                decode::<GetDistancesRequest>(&raw(&req), None, guid(3), SequenceNumber::from(9)).expect("decode");
            assert_eq!(got, req);
            assert_eq!(
                id,
                RequestId::Bare(SampleIdentity { writer_guid: guid(3), sequence_number: SequenceNumber::from(9) })
            );
        }
        let path = SaveMapRequest { path: "/tmp/some/map.edtmap".into() };
        let (id, got) = decode::<SaveMapRequest>(&raw(&path), None, guid(3), SequenceNumber::from(2)).expect("decode");
        assert_eq!((matches!(id, RequestId::Bare(_)), got), (true, path));
    }

    #[test]
    fn a_declared_length_the_bytes_cannot_hold_is_refused_before_decoding() {
        // u32::MAX points declared in 12 bytes, in both layouts.
        let mut bare = vec![0xff, 0xff, 0xff, 0xff];
        bare.extend([0; 8]);
        let bare = Raw { bytes: Bytes::from(bare), encoding: RepresentationIdentifier::CDR_LE };
        let err =
            decode::<GetDistancesRequest>(&bare, None, guid(3), SequenceNumber::from(1)).expect_err("cannot hold them");
        assert!(err.contains("4294967295 elements"), "{err}");
        let mut header = vec![1; 16];
        header.extend(bare.bytes.iter());
        let header = Raw { bytes: Bytes::from(header), encoding: RepresentationIdentifier::CDR_LE };
        assert!(decode::<GetDistancesRequest>(&header, None, guid(3), SequenceNumber::from(1)).is_err());
        assert_eq!(declared_fits(&raw(&request()).bytes, RepresentationIdentifier::CDR_LE, 0, 24), Ok(()));
    }

    #[test]
    fn a_request_over_the_size_limit_is_refused_undecoded_to_its_client() {
        let cyclone = raw(&(0xdead_beef_u64, 5_i64, request()));
        let max = cyclone.bytes.len() - 1;
        let refused = receive_one::<GetDistancesRequest>(&cyclone, None, guid(3), SequenceNumber::from(1), max)
            .expect_err("too large");
        assert_eq!(
            refused,
            Refused::TooLarge { id: RequestId::Header { client: 0xdead_beef, seq: 5 }, bytes: max + 1, max_bytes: max }
        );
        let fast = SampleIdentity { writer_guid: guid(7), sequence_number: SequenceNumber::UNKNOWN };
        let refused =
            receive_one::<GetDistancesRequest>(&raw(&request()), Some(fast), guid(3), SequenceNumber::from(12), 8)
                .expect_err("too large");
        assert!(
            matches!(refused, Refused::TooLarge { id: RequestId::Bare(SampleIdentity { writer_guid, sequence_number }), .. } if writer_guid == guid(7) && sequence_number == SequenceNumber::from(12))
        );
        assert!(receive_one::<GetDistancesRequest>(&cyclone, None, guid(3), SequenceNumber::from(1), max + 1).is_ok());
    }

    #[test]
    fn a_request_that_fits_no_layout_is_an_error() {
        let bytes = Raw { bytes: Bytes::from_static(&[0xff; 40]), encoding: RepresentationIdentifier::CDR_LE };
        assert!(decode::<GetDistancesRequest>(&bytes, None, guid(3), SequenceNumber::from(1)).is_err());
        let truncated =
            Raw { bytes: Bytes::from_static(&[2, 0, 0, 0, 0, 0, 0, 0, 1]), encoding: RepresentationIdentifier::CDR_LE };
        let fast = SampleIdentity { writer_guid: guid(7), sequence_number: SequenceNumber::UNKNOWN };
        assert!(decode::<GetDistancesRequest>(&truncated, Some(fast), guid(3), SequenceNumber::from(1)).is_err());
    }
}
