"""std_msgs/Header from a frame id and a stamp, checked; a stamp as integer nanoseconds."""
from builtin_interfaces.msg import Time
from std_msgs.msg import Header

from msg_adapters.errors import AdapterError


def make_header(frame_id: str, stamp) -> Header:
    """Header(frame_id, stamp); `stamp` is a builtin_interfaces Time or anything with `.to_msg()` (rclpy Time)."""
    if not isinstance(frame_id, str):
        raise AdapterError(f"frame_id must be a str, got {type(frame_id).__name__}")
    if not isinstance(stamp, Time) and hasattr(stamp, "to_msg"):
        stamp = stamp.to_msg()
    if not isinstance(stamp, Time):
        raise AdapterError(f"stamp must be a builtin_interfaces.msg.Time or rclpy Time, got {type(stamp).__name__}")
    return Header(frame_id=frame_id, stamp=stamp)


def stamp_nanoseconds(stamp) -> int:
    """A builtin_interfaces Time (rclpy's or rosbags') as integer nanoseconds: exact, unlike float seconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
