"""How the pages are lit: without viser's environment map (issue #26.2, "keeps up on a
modest laptop").

**Decision** (measured): no page uses viser's default image-based lighting (the
"warehouse" environment map). A page drawing in software (no GPU: Chromium's SwiftShader,
the case on this 2-core machine and on a laptop whose browser blocks its GPU) pays for the
map's lookups in every lit pixel of every frame. CPU of Chromium's GPU process per drawn
frame at 1280x800, full resolution, default abdomen (2026-12-02, one block of runs, the
measure of ``bench/viewer_pixels.py``):

===========================  =================  ===============================
page                         with the map [ms]  without it [ms]
===========================  =================  ===============================
trainee (the scope's light)  3,940              556
experimenter (third person)  5,435              441 (450 with the fill below)
===========================  =================  ===============================

Turning the organs' shadows off instead changed nothing (3,837 ms). On the trainee page the
endoscope's own lights (:class:`vasim.viewer.endoscope.ScopeLight`) replace it, as in a
real abdomen, where the scope's light is the only light. The third-person pages (the
experimenter's, the MRCP station's) keep viser's default directional lights and get a
hemisphere light as the map's soft fill (:func:`third_person_lighting`), so shapes still
read in the organs' shading.
"""

from __future__ import annotations

import viser

FILL_INTENSITY = 1.5
"""The hemisphere fill of the third-person pages (chosen by eye against the map's look:
the bowel loops' shading reads as with the map, not darker)."""


def no_environment_map(server: viser.ViserServer) -> None:
    """Turns viser's environment map off for every page of ``server`` (module doc)."""
    server.scene.configure_environment_map(None)


def third_person_lighting(server: viser.ViserServer) -> None:
    """The experimenter's and the MRCP station's lighting: viser's default lights, no
    environment map, a hemisphere fill (module doc)."""
    no_environment_map(server)
    server.scene.add_light_hemisphere("/lighting/fill", sky_color=(255, 255, 255),
                                      ground_color=(90, 70, 60), intensity=FILL_INTENSITY)


__all__ = ["FILL_INTENSITY", "no_environment_map", "third_person_lighting"]
