"""Procedural Mitsuba 3 scenes for the synthetic camera, with trajectories and a render cache.

Importing this package is cheap: Mitsuba is imported only when something is
rendered (and only after a child process has shown the variant is safe), and
colour-science only when a scene is built.

Quick use::

    import scenes
    scene = scenes.get_scene("forest_winter", seed=1)
    traj = scene.trajectory(duration_s=20)
    left = traj.pose(3.0)
    img = scenes.render(scene, left, width=480, height=300, spp=64, seed=0)
    right = scenes.render(scene, scenes.stereo_right(left), width=480, height=300, spp=64, seed=0)
    scenes.dynamic_range_db(img)
"""

from __future__ import annotations

from scenes import library as _library  # registers the scenes  # noqa: F401
from scenes import trajectory
from scenes.base import SCENES, Scene, code_fingerprint, get_scene
from scenes.cache import default_cache_dir, render_key
from scenes.camera import DEFAULT_FOV_DEG, intrinsics, intrinsics_matrix, pose_to_mitsuba, project
from scenes.dynamic_range import dynamic_range_db, luminance
from scenes.errors import RenderError, SceneError
from scenes.library import forest_edge, forest_summer, forest_winter, static_lab, sun_glare
from scenes.render import effective_spp, render, render_depth, render_with_info
from scenes.spp import SensorNoise, SppSelection, measure_render_noise, select_spp
from scenes.trajectory import BASELINE_M, WALKING_SPEED_MPS, Trajectory, look_pose, static, stereo_right, walk
from scenes.variant import choose_variant

__all__ = [
    "SCENES",
    "Scene",
    "get_scene",
    "forest_winter",
    "forest_summer",
    "sun_glare",
    "forest_edge",
    "static_lab",
    "render",
    "render_with_info",
    "render_depth",
    "effective_spp",
    "choose_variant",
    "intrinsics",
    "intrinsics_matrix",
    "pose_to_mitsuba",
    "project",
    "DEFAULT_FOV_DEG",
    "dynamic_range_db",
    "luminance",
    "select_spp",
    "measure_render_noise",
    "SensorNoise",
    "SppSelection",
    "trajectory",
    "Trajectory",
    "walk",
    "static",
    "look_pose",
    "stereo_right",
    "BASELINE_M",
    "WALKING_SPEED_MPS",
    "default_cache_dir",
    "render_key",
    "code_fingerprint",
    "SceneError",
    "RenderError",
]
