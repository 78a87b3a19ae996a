"""ROS 2 messages and the edtmap services as DDS carries them, for a plain
Cyclone DDS participant (no rclpy).

Naming, as every ROS 2 RMW uses it:
  * message ``pkg/msg/Name``  -> DDS type ``pkg::msg::dds_::Name_``,
    topic ``/a/b`` -> DDS topic ``rt/a/b``;
  * service ``pkg/srv/Name``  -> types ``pkg::srv::dds_::Name_Request_`` and
    ``Name_Response_``, service ``/a/b`` -> topics ``rq/a/bRequest`` and
    ``rr/a/bReply``.

Every struct is ``@final`` and writers and readers should use plain CDR
(XCDR1, see ``XCDR1`` below): that is what the RMWs and RustDDS put on the
wire. ``uint8[]`` fields are ``sequence[uint8]``: a ``bytes`` field
serializes, but cyclonedds 11 cannot build its XTypes type object and
refuses the topic. Such a sequence reads back as a list of ints.

Services follow rmw_cyclonedds_cpp: each request and reply sample starts
with its request header ``{uint64 guid; int64 seq}`` (not part of the type
name), then the ROS fields. The client picks the guid and the sequence
number; the server echoes both in the reply.
"""
from dataclasses import dataclass, field

import cyclonedds.idl.annotations as annotate
from cyclonedds.core import Policy
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float32, float64, int8, int32, int64, sequence, uint8, uint32, uint64

# Plain CDR (XCDR1): cyclonedds would otherwise offer XCDR2, which aligns
# 8-byte values to 4 bytes and so differs from what ROS 2 and RustDDS send.
XCDR1 = Policy.DataRepresentation(use_cdrv0_representation=True)

# sensor_msgs/PointField datatype codes.
POINTFIELD_FLOAT32 = 7


def _ros(pkg: str, name: str) -> str:
    return f"{pkg}::msg::dds_::{name}_"


# --- builtin_interfaces, std_msgs -------------------------------------------

@dataclass
@annotate.final
class Time(IdlStruct, typename=_ros("builtin_interfaces", "Time")):
    sec: int32 = 0
    nanosec: uint32 = 0

    @staticmethod
    def from_s(t: float) -> "Time":
        ns = round(t * 1e9)
        return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def to_s(self) -> float:
        return self.sec + self.nanosec * 1e-9


@dataclass
@annotate.final
class Header(IdlStruct, typename=_ros("std_msgs", "Header")):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


# --- geometry_msgs ------------------------------------------------------------

@dataclass
@annotate.final
class Vector3(IdlStruct, typename=_ros("geometry_msgs", "Vector3")):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
@annotate.final
class Point(IdlStruct, typename=_ros("geometry_msgs", "Point")):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
@annotate.final
class Quaternion(IdlStruct, typename=_ros("geometry_msgs", "Quaternion")):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@dataclass
@annotate.final
class Transform(IdlStruct, typename=_ros("geometry_msgs", "Transform")):
    translation: Vector3 = field(default_factory=Vector3)
    rotation: Quaternion = field(default_factory=Quaternion)


@dataclass
@annotate.final
class TransformStamped(IdlStruct, typename=_ros("geometry_msgs", "TransformStamped")):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    transform: Transform = field(default_factory=Transform)


@dataclass
@annotate.final
class Pose(IdlStruct, typename=_ros("geometry_msgs", "Pose")):
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


# --- tf2_msgs ------------------------------------------------------------------

@dataclass
@annotate.final
class TFMessage(IdlStruct, typename=_ros("tf2_msgs", "TFMessage")):
    transforms: sequence[TransformStamped] = field(default_factory=list)


# --- sensor_msgs ------------------------------------------------------------------

@dataclass
@annotate.final
class PointField(IdlStruct, typename=_ros("sensor_msgs", "PointField")):
    name: str = ""
    offset: uint32 = 0
    datatype: uint8 = 0
    count: uint32 = 0


@dataclass
@annotate.final
class PointCloud2(IdlStruct, typename=_ros("sensor_msgs", "PointCloud2")):
    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    fields: sequence[PointField] = field(default_factory=list)
    is_bigendian: bool = False
    point_step: uint32 = 0
    row_step: uint32 = 0
    data: sequence[uint8] = field(default_factory=list)
    is_dense: bool = False


# --- nav_msgs ---------------------------------------------------------------------

@dataclass
@annotate.final
class MapMetaData(IdlStruct, typename=_ros("nav_msgs", "MapMetaData")):
    map_load_time: Time = field(default_factory=Time)
    resolution: float32 = 0.0
    width: uint32 = 0
    height: uint32 = 0
    origin: Pose = field(default_factory=Pose)


@dataclass
@annotate.final
class OccupancyGrid(IdlStruct, typename=_ros("nav_msgs", "OccupancyGrid")):
    header: Header = field(default_factory=Header)
    info: MapMetaData = field(default_factory=MapMetaData)
    data: sequence[int8] = field(default_factory=list)


# --- diagnostic_msgs ----------------------------------------------------------------

@dataclass
@annotate.final
class KeyValue(IdlStruct, typename=_ros("diagnostic_msgs", "KeyValue")):
    key: str = ""
    value: str = ""


@dataclass
@annotate.final
class DiagnosticStatus(IdlStruct, typename=_ros("diagnostic_msgs", "DiagnosticStatus")):
    level: uint8 = 0  # IDL octet (ROS `byte`): the same single byte on the wire
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: sequence[KeyValue] = field(default_factory=list)


@dataclass
@annotate.final
class DiagnosticArray(IdlStruct, typename=_ros("diagnostic_msgs", "DiagnosticArray")):
    header: Header = field(default_factory=Header)
    status: sequence[DiagnosticStatus] = field(default_factory=list)


# --- edtmap_msgs/srv/GetDistances, with rmw_cyclonedds' request header ------------

# GetDistances_Response.states
STATE_OUTSIDE, STATE_UNKNOWN, STATE_FREE, STATE_OCCUPIED = 0, 1, 2, 3


@dataclass
@annotate.final
class GetDistances_Request(IdlStruct, typename="edtmap_msgs::srv::dds_::GetDistances_Request_"):
    client_guid: uint64 = 0  # request header
    seq: int64 = 0           # request header
    points: sequence[Point] = field(default_factory=list)
    signed_distance: bool = False


@dataclass
@annotate.final
class GetDistances_Response(IdlStruct, typename="edtmap_msgs::srv::dds_::GetDistances_Response_"):
    client_guid: uint64 = 0  # request header, echoed
    seq: int64 = 0           # request header, echoed
    success: bool = False
    message: str = ""
    map_stamp: Time = field(default_factory=Time)
    distances: sequence[float64] = field(default_factory=list)
    gradients: sequence[Vector3] = field(default_factory=list)
    states: sequence[uint8] = field(default_factory=list)
    saturated: sequence[bool] = field(default_factory=list)
