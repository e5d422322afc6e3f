"""Which depth a camera gives, told by the board being flat: z, along the optical axis (REP 118,
the Kinect, most ROS drivers), or the radial distance, the light's path (what a ToF pixel
measures, and raw PMD sensors give).

Read in the wrong convention a flat board bows: the radial distance along the ray (x, y, 1) is
z times sqrt(1 + x^2 + y^2), 6 % more at the edge of a 200x200 PMD camera's view and 22 % at a
Kinect v2's corners. So a plane fits the white squares' depth better in one convention than in
the other. Both fits take the same samples (those the plane in the first convention kept, which a
bow does not cut: ``planarize.on_surface`` allows for one) and the same three parameters, so the
log-likelihood ratio of one over the other is n/2 log(RSS_z / RSS_radial), divided by how many
times a pixel's noise is shared with its neighbours (``noise_spread``: a driver's smoothing
would otherwise count one bow many times). Summed over the views it decides beyond ``DECISIVE``;
short of it the two read alike and z, ROS's convention, is taken.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import DEPTH_CONVENTIONS
from .planarize import DepthSamples, Plane, directions, fit_plane_to, noise_spread

DECISIVE = 10.0   # log-likelihood: odds of e^10 (22000) to one
_WHAT = {"z": "z-depth (along the optical axis)", "radial": "the radial distance (the light's path)"}


@dataclass(frozen=True)
class ConventionEvidence:
    """The log-likelihood of radial over z depth (``statistic``), summed over ``views``."""

    statistic: float
    views: int

    @property
    def read_as(self) -> str | None:
        """The convention the boards are flat in, or None where both read alike."""
        if abs(self.statistic) < DECISIVE:
            return None
        return "radial" if self.statistic > 0 else "z"

    def choice(self) -> tuple[str, str]:
        """The convention to calibrate in where none was given, and why."""
        found = self.read_as
        if found is None:
            return "z", (f"depth convention z: the boards are about as flat read as z-depth as read as the radial "
                         f"distance (log-likelihood {self.statistic:+.1f} over {self.views} views, decisive beyond "
                         f"{DECISIVE:g}), and z is ROS's; give the convention if the camera gives the radial distance")
        return found, (f"depth convention {found}: the boards are flat read as {_WHAT[found]} and bow read as "
                       f"{_WHAT[_other(found)]} (log-likelihood {abs(self.statistic):.0f} over {self.views} views, "
                       f"decisive beyond {DECISIVE:g})")

    def doubt(self, given: str) -> str | None:
        """What to say where the convention given is the one the boards bow in."""
        if self.read_as not in (None, given):
            return (f"the depth looks like {_WHAT[self.read_as]}, not the {_WHAT[given]} given: the boards bow read "
                    f"so and are flat read the other way (log-likelihood {abs(self.statistic):.0f} over "
                    f"{self.views} views): is the depth convention right? ('auto' lets the data choose)")
        return None


def _other(convention: str) -> str:
    return next(c for c in DEPTH_CONVENTIONS if c != convention)


def convention_evidence(samples: list[DepthSamples | None], planes: list[Plane | None],
                        params: np.ndarray) -> ConventionEvidence:
    """How much flatter each view's white squares (``samples``, with the ``planes`` fitted to them
    in either convention, whose inliers are compared) are read as radial depth than as z."""
    total, views = 0.0, 0
    for smp, plane in zip(samples, planes):
        if smp is None or plane is None:
            continue
        white = smp.subset(~smp.black).subset(plane.inliers)
        residuals = {}
        for convention in DEPTH_CONVENTIONS:
            u = directions(white.pixels, params, convention)
            coef = fit_plane_to(u, white.depth, white.pixels, white.black).coef
            residuals[convention] = white.depth - 1.0 / (u @ coef)
        rss = {c: float(r @ r) for c, r in residuals.items()}
        if min(rss.values()) <= 0:
            continue
        best = min(rss, key=rss.get)
        shared = noise_spread(white.pixels, residuals[best] / np.sqrt(rss[best] / len(white.depth)))
        total += len(white.depth) / 2 * np.log(rss["z"] / rss["radial"]) / shared
        views += 1
    return ConventionEvidence(float(total), views)
