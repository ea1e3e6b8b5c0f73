"""The procedural scenes.

Each public function here is a scene builder registered in
:data:`scenes.SCENES`: its keyword-only parameters are the scene's named
parameters.  The matching ``_describe_*`` function builds the geometry,
textures and lighting as a :class:`~scenes.description.SceneDescription`.

Conventions: world frame in metres, z up, ground at z = 0; the default walk
goes along +x from the origin, on a trail kept free of trunks.  Sun azimuth is
measured from +x towards +y.  Radiometry: the sun's irradiance (W m^-2 on a
surface facing it) and the sky's share of it set the absolute scale; albedos
are those of the real materials (fresh snow 0.8-0.95, conifer needles and bark
0.02-0.15, forest litter 0.03-0.25).  The sun is a directional emitter, except
in ``sun_glare`` where it must show in the image (a distant sphere of the sun's
angular size carrying the same irradiance); the sky is an environment map
holding ``sky_fraction`` of the sun's irradiance.  The path tracer stops after
one indirect bounce (``max_depth`` 3), which keeps renders fast and leaves
multiply-reflected light out: measured against ``max_depth`` 6 at 96x60, shade
is 3 % darker in ``forest_winter`` and 20 % darker inside the ``forest_edge``
stand, which moves the dynamic range by less than 1 dB.

Dynamic range comes from the physics, not from exposure tricks: sunlit snow
(~160 W m^-2 sr^-1) against needles and bark lit by a little sky or by light
bounced once.  ``forest_edge`` closes the sky off entirely with a roof of
needles; what little daylight a dense canopy passes is modelled as a faint
downward emission of that roof (``canopy_transmittance``), which keeps the
inside dark but sampled without the noise of light that only enters through
the opening.

The package: one module per scene (:mod:`~scenes.library.forest_winter`,
:mod:`~scenes.library.forest_summer`, :mod:`~scenes.library.sun_glare`,
:mod:`~scenes.library.forest_edge`, :mod:`~scenes.library.static_lab`), each registering its
builder in :data:`scenes.SCENES` (:func:`scenes.base.register_scene`) when imported here, in
this order; :mod:`~scenes.library.parts` holds what they share.
"""

from __future__ import annotations

from scenes.library.forest_winter import forest_winter
from scenes.library.forest_summer import forest_summer
from scenes.library.sun_glare import sun_glare
from scenes.library.forest_edge import forest_edge
from scenes.library.static_lab import static_lab
from scenes.library.parts import (
    SNOW_DETAIL,
    SNOW_DETAIL_RANGE,
    SNOW_RELIEF,
    BARK_DETAIL_RANGE,
    NEEDLE_DETAIL,
    NEEDLE_DETAIL_RANGE,
    NEEDLE_ALBEDO,
)

__all__ = ["forest_winter", "forest_summer", "sun_glare", "forest_edge", "static_lab"]
