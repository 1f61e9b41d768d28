"""Where an estimate's result goes: ``~/poses``, ``~/markers``, ``~/views``, ``~/object_cloud``, ``~/object_pose``
(latched), ``~/next_view`` (latched) and, when on, TF.

Lifecycle publishers: they publish only while the node is active. Deactivating does not destroy them, so the
last result stays latched: a subscriber that joins later, the node active or not, still gets it; activating
publishes nothing again.
"""
from __future__ import annotations

from geometry_msgs.msg import PoseArray, PoseStamped
from rclpy.lifecycle import LifecycleNode
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image, PointCloud2
from visualization_msgs.msg import MarkerArray

from idpose_core.pipeline import PipelineResult, views_mosaic
from idpose_interfaces.action import EstimatePoses
from idpose_ros.node.tf_broadcast import PoseBroadcaster
from msg_adapters import array_to_image, box_marker, camera_markers

MARKER_DEPTH = 0.15  # frustum depth as a share of object_distance
# Reliable and latched: a subscriber that joins late still gets the last result.
RESULT_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


class ResultPublisher:
    """The node's result topics, and TF when ``publish_tf``."""

    def __init__(self, node: LifecycleNode, publish_tf: bool) -> None:
        self._poses = node.create_lifecycle_publisher(PoseArray, "~/poses", RESULT_QOS)
        self._markers = node.create_lifecycle_publisher(MarkerArray, "~/markers", RESULT_QOS)
        self._views = node.create_lifecycle_publisher(Image, "~/views", RESULT_QOS)
        self._cloud = node.create_lifecycle_publisher(PointCloud2, "~/object_cloud", RESULT_QOS)
        self._object_pose = node.create_lifecycle_publisher(PoseStamped, "~/object_pose", RESULT_QOS)
        self._next_view = node.create_lifecycle_publisher(PoseStamped, "~/next_view", RESULT_QOS)
        self._tf = PoseBroadcaster(node, node.get_logger().warning) if publish_tf else None

    def publish(self, result: PipelineResult, message: EstimatePoses.Result, tf_prefix: str) -> None:
        """Poses (the result's own PoseArray), markers, the views the model saw, the object's cloud and pose (the
        result's own, only when the estimate has a cloud: an estimate without depth leaves the last ones) and TF;
        the markers are sized by the distance the poses use (measured from depth when the anchor had it) and add
        the object's box when there is one; the next view (the result's own) and its TF frame."""
        poses = message.poses
        self._poses.publish(poses)
        markers = camera_markers(result.poses, poses.header.frame_id, poses.header.stamp,
                                 depth=MARKER_DEPTH * result.object_distance)
        if result.object is not None:
            markers.markers.append(box_marker(result.object.pose, result.object.size, poses.header.frame_id,
                                              poses.header.stamp))
            self._cloud.publish(message.object_cloud)
            self._object_pose.publish(message.object_pose)
        self._markers.publish(markers)
        mosaic = array_to_image(views_mosaic(result.preprocessed.images), "rgb8")
        mosaic.header = poses.header
        self._views.publish(mosaic)
        self._next_view.publish(message.next_view)
        if self._tf is not None:
            self._tf.broadcast(poses, tf_prefix, message.next_view)
