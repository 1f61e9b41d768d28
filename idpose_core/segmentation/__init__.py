"""Depth segmentation: the target object cut out of an RGB-D view by its depth, with no learnt weights.

An object on a table stands above the table's plane and apart from its neighbours in depth, so an aligned depth
image and the intrinsics suffice to cut it out of any scene, whatever the object: ``depth_cut`` finds the support
plane (``support_plane``), splits what stands on it into pieces, joins the parts of one object, leaves out the
room, takes the target's piece and lets GrabCut settle its boundary; ``object_centre`` and ``object_distance``
give the object's position from its visible points, for the scale of its pose. ``DepthSegmentationError`` says
why depth cannot do it, so a caller can fall back to the colour methods. Depth is in metres in the camera's
optical frame; 0 or NaN means no reading. No ROS here.
"""
from idpose_core.segmentation.cut import DepthCut, depth_cut
from idpose_core.segmentation.distance import object_centre, object_distance
from idpose_core.segmentation.errors import DepthSegmentationError
from idpose_core.segmentation.grabcut import grabcut_refine
from idpose_core.segmentation.plane import Plane, backproject, support_plane

__all__ = ["DepthCut", "DepthSegmentationError", "Plane", "backproject", "depth_cut", "grabcut_refine",
           "object_centre", "object_distance", "support_plane"]
