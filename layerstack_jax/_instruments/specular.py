r"""Specular measurements: :class:`Specular` — R, T or A of the stack at an angle, natural light.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx

from .._base.custom_types import RealLike
from .._base.validate import (
    LayerstackError,
    check_angle_deg,
)
from .._stacks.recursion import join_interfaces, natural
from .geometry import OpticalGeometry
from .optical_parts import _incidence, _optics, _scalar_text, _split


class Specular(OpticalGeometry):
    """Specular measurement at ``angle_deg``: ``quantity`` 'R' (reflectance), 'T' (transmittance
    into the exit medium) or 'A' (absorptance, 1 − R − T), for natural light.

    ``angle_deg`` in degrees from the normal, in [0, 90): a scalar, or an array ``(*angle)`` that
    adds leading axes to the :func:`reflectance` output ``(*angle, wl)`` (dimensionless fractions).
    """

    angle_deg: RealLike = 0.0
    quantity: str = eqx.field(static=True, default="R")

    spelling: ClassVar[str] = "specular:ANGLE[:R|T|A]"
    reads_diffuse_light: ClassVar[bool] = False

    def __check_init__(self):
        if self.quantity not in ("R", "T", "A"):
            raise LayerstackError(f"Specular.quantity must be 'R', 'T' or 'A', got {self.quantity!r}")
        check_angle_deg("Specular.angle_deg", self.angle_deg)

    def optics(self, rs, background, nodes):
        return _optics(self, rs, _incidence(rs, check_angle_deg("Specular.angle_deg", self.angle_deg)), nodes=nodes)

    def read(self, rs, o, background):
        front = join_interfaces(rs, o.incidence, both_sides=False)
        R, T = natural(front.R_front), natural(front.T_front)
        return {"R": R, "T": T, "A": 1.0 - R - T}[self.quantity]

    @property
    def label(self):
        return f"specular:{_scalar_text(self.angle_deg)}:{self.quantity}"

    @property
    def quantity_label(self):
        return {"R": "reflectance", "T": "transmittance", "A": "absorptance"}[self.quantity]

    @classmethod
    def parse(cls, text):
        if not text.startswith("specular"):
            return None
        parts = _split(text, "specular", 2, 3)
        return cls(float(parts[1]), parts[2].upper() if len(parts) > 2 else "R")


