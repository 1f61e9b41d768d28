"""Depth fusion: the diffusion estimate refined by registering the views' depth, and the object's fused cloud.

``view_cloud`` cuts a view's object points out of its depth; ``refine_with_depth`` registers them into the
anchor's frame, seeded by the diffusion poses, gated per view; ``object_frame`` gives the fused cloud's pose
and box; ``cross_view_masks`` gives each posed view's mask a second pass from the fused cloud. No ROS here.
"""
from idpose_core.depth_fusion.clouds import ObjectCloud, fused_cloud, view_cloud
from idpose_core.depth_fusion.mask_pass import MaskPass, cross_view_masks
from idpose_core.depth_fusion.object_frame import ObjectFrame, object_frame
from idpose_core.depth_fusion.refinement import (
    DepthRefinement,
    RefinementSettings,
    ViewRefinement,
    refine_with_depth,
)
from idpose_core.depth_fusion.registration import Registration, register

__all__ = ["DepthRefinement", "MaskPass", "ObjectCloud", "ObjectFrame", "RefinementSettings", "Registration",
           "ViewRefinement", "cross_view_masks", "fused_cloud", "object_frame", "refine_with_depth", "register",
           "view_cloud"]
