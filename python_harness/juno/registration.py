"""Registration of a LIDAR scan against a measured traverse, without simulating the rover.

A misregistered scan puts the terrain's features (the mound) in the wrong place, and the
rover's measured height and pitch along its measured path show where they really are.  The
chassis reference point rides at a nearly constant height above the mean ground under its four
wheels, and its pitch follows the ground's slope between the axles, so for a trial registration
(offset o = (ox, oy) m, raise oz m, yaw psi rad: grid point q appears at o + Rz(psi) q, as the
FMU's ``terrain.offset*`` parameters place it) the predicted measurements are

    z(t)     = h0 + mean over wheels of [G(Rz(-psi) (p_w(t) - o)) + oz]
    pitch(t) = a_p atan((mean rear ground - mean front ground) / wheelbase)   (positive nose down)
    roll(t)  = a_r atan((mean left ground - mean right ground) / track)       (positive left side up)

with p_w the wheel positions from the measured pose and the rover's geometry, G the gridded
scan, and h0 the chassis height above flat ground (the mean measured height on the drawbar
runs, which are on flat ground at z = 0).  The attitude gains a_p and a_r are nuisance
parameters, fitted with the offsets and then dropped: the chassis tilts more than the ground
between its wheels, because on a slope the load moves to the downhill wheels, which sink
deeper.  Measured on synthetic campaigns (the FMU as the truth), a_p is 1.12-1.17 and a_r
1.00-1.07.  With a_p fixed at 1, the search turned the scan by up to its 7 deg bound, which
makes the mound steeper along the path to match the larger measured pitch. On 7 misregistered
campaigns that put the mound 10-16 cm from where it is; with the gains fitted, 2-12 cm
(median 5.5 cm).  Least squares over the four offsets and the two gains from a grid of starts
gives the registration; it is kept only if it explains the measurements EVIDENCE_RATIO times
better than the scan as it is.  Cheap (no FMU): about 0.2 s for a 30 s run.

Assumptions, named: sinkage is the same on the mound as on the flat (it changes by millimetres
with the load transfer); the rocker follows the ground so the four-wheel mean is what the
chassis rides on, the differential makes the chassis pitch the mean of the two rockers', and
the chassis rolls with the difference of the two sides' mean heights.  Roll is what pins the
sideways offset: a traverse along one flank of a mound sees its lateral slope only in roll (on
a 30 s synthetic run, the truth registration leaves 0.008 rad RMS roll residual against
0.11 rad RMS roll; without roll the fit put the scan 0.37 m off sideways).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from .pointcloud import Grid

#: Trial offsets of the starting grid: shifts (m) in x and y, yaw (rad).
START_SHIFTS = (-0.3, -0.15, 0.0, 0.15, 0.3)
START_YAWS = (-0.06, -0.03, 0.0, 0.03, 0.06)
#: Weights: the height's and the pitch's typical model error (not the sensor noise: the chassis
#: does not follow the ground exactly), m and rad.
SIGMA_Z = 0.01
SIGMA_PITCH = 0.01
SIGMA_ROLL = 0.01
#: The registrations searched: shifts up to 0.6 m, raises up to 10 cm, turns up to 7 deg.  A
#: traverse that crosses no terrain feature leaves the registration undetermined, and an
#: unbounded search then wanders (a 2 m, 29 deg "registration" was found on such a run).
LIMITS = np.array([0.6, 0.6, 0.1, 0.12])
#: How much better than the unshifted scan a registration must explain the measurements (ratio
#: of the two least-squares costs, each with its best attitude gains) to be taken as evidence of
#: a misregistration.  The kinematic model's own error leaves room for any registration to
#: improve a little: on 20 synthetic campaigns with nothing misregistered the ratio was 1.10-2.58,
#: and in the detection studies such small registrations were named as false causes by the
#: terrain replay (which a 5 cm move of the mound can change by half): 2 of those 20 campaigns
#: before the tilt gains, 1 after (ratio 1.10).  Set from that null distribution (1.5 times its
#: largest value), not from the misregistered campaigns (ratios 5.3-74).
EVIDENCE_RATIO = 4.0
#: Bounds of the attitude gains (pitch, roll): the chassis tilts by 0.7-1.5 times the ground's
#: slope between its wheels (measured 1.00-1.17 on the synthetic campaigns).
GAIN_LIMITS = (0.7, 1.5)


@dataclass(frozen=True)
class Traverse:
    """A measured terrain run at the total station's sample times: position (m), yaw, pitch
    and roll (rad, interpolated from the IMU), and the rover's wheelbase and track (m)."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    yaw: np.ndarray
    pitch: np.ndarray | None
    wheelbase: float
    track: float
    roll: np.ndarray | None = None


def wheel_points(tr: Traverse) -> tuple[np.ndarray, np.ndarray]:
    """World x, y (m) of the four wheels below their hubs, shape (n, 4): FL, RL, FR, RR."""
    c, s = np.cos(tr.yaw), np.sin(tr.yaw)
    half_l, half_w = tr.wheelbase / 2, tr.track / 2
    fx = np.array([half_l, -half_l, half_l, -half_l])
    fy = np.array([half_w, half_w, -half_w, -half_w])
    px = tr.x[:, None] + c[:, None] * fx - s[:, None] * fy
    py = tr.y[:, None] + s[:, None] * fx + c[:, None] * fy
    return px, py


def ground_under_wheels(grid: Grid, tr: Traverse, offset: np.ndarray) -> np.ndarray:
    """Ground height (m) under each wheel, shape (n, 4), for offset (ox, oy, oz, yaw)."""
    ox, oy, oz, yaw = offset
    px, py = wheel_points(tr)
    dx, dy = px - ox, py - oy
    c, s = np.cos(yaw), np.sin(yaw)
    return grid.height(c * dx + s * dy, -s * dx + c * dy) + oz


def predicted_attitude(ground: np.ndarray, tr: Traverse) -> tuple[np.ndarray, np.ndarray]:
    """Chassis pitch and roll (rad) that the ground under the wheels (m, shape (n, 4): FL, RL,
    FR, RR) gives: pitch positive nose down (the FMU's convention), roll positive left side up."""
    slope = ((ground[:, 1] + ground[:, 3]) - (ground[:, 0] + ground[:, 2])) / (2 * tr.wheelbase)
    side_slope = ((ground[:, 0] + ground[:, 1]) - (ground[:, 2] + ground[:, 3])) / (2 * tr.track)
    return np.arctan(slope), np.arctan(side_slope)


def residuals(offset: np.ndarray, grid: Grid, tr: Traverse, h0: float,
              gains: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """Scaled residuals of height (and pitch and roll, if measured) for a trial registration,
    with the chassis tilting ``gains`` (pitch, roll) times the ground's slope."""
    g = ground_under_wheels(grid, tr, offset)
    r = [(tr.z - h0 - g.mean(axis=1)) / SIGMA_Z]
    pitch, roll = predicted_attitude(g, tr)
    if tr.pitch is not None:
        r.append((tr.pitch - gains[0] * pitch) / SIGMA_PITCH)
    if tr.roll is not None:
        r.append((tr.roll - gains[1] * roll) / SIGMA_ROLL)
    return np.concatenate(r)


def register(grid: Grid, tr: Traverse, h0: float | None) -> dict[str, float]:
    """The registration offsets (FMU names ``terrain.offsetX/Y/Z/Yaw``) that best explain the
    measured height, pitch and roll, or all 0 (the scan as it is) unless they explain them
    EVIDENCE_RATIO times better than the scan as it is.  With ``h0`` None (no flat-ground run to
    measure the chassis height on), the raise cannot be told from the chassis height and is left
    at 0."""
    fit_z = h0 is not None
    h = 0.0 if h0 is None else h0

    def res(v: np.ndarray) -> np.ndarray:
        """v: the four offsets, then the pitch and roll gains."""
        off = np.array([v[0], v[1], v[2] if fit_z else 0.0, v[3]])
        r = residuals(off, grid, tr, h, (v[4], v[5]))
        if not fit_z:
            r[:len(tr.z)] -= np.mean(r[:len(tr.z)])   # the height offset is free
        return r

    starts = [np.array([dx, dy, 0.0, yaw, 1.0, 1.0])
              for dx in START_SHIFTS for dy in START_SHIFTS for yaw in START_YAWS]
    costs = [float(np.sum(res(v) ** 2)) for v in starts]
    lower = np.concatenate([-LIMITS, [GAIN_LIMITS[0]] * 2])
    upper = np.concatenate([LIMITS, [GAIN_LIMITS[1]] * 2])
    best = None
    for i in np.argsort(costs)[:4]:
        fit = least_squares(res, starts[i], x_scale=np.array([0.1, 0.1, 0.01, 0.02, 0.1, 0.1]), max_nfev=300,
                            bounds=(lower, upper))
        if best is None or fit.cost < best.cost:
            best = fit
    as_scanned = least_squares(lambda g: res(np.array([0.0, 0.0, 0.0, 0.0, g[0], g[1]])), np.ones(2),
                               bounds=([GAIN_LIMITS[0]] * 2, [GAIN_LIMITS[1]] * 2))
    ox, oy, oz, yaw = best.x[:4]
    if not as_scanned.cost >= EVIDENCE_RATIO * best.cost:
        ox = oy = oz = yaw = 0.0
    return {"terrain.offsetX": float(ox), "terrain.offsetY": float(oy),
            "terrain.offsetZ": float(oz) if fit_z else 0.0, "terrain.offsetYaw": float(yaw)}


#: The FMU's defaults (modelDescription), used when the campaign does not override them.
DEFAULT_WHEELBASE = 0.82
DEFAULT_TRACK = 1.35
SETTLING = 2.0   # s at the start of a run left out (the rover starts from rest)


def traverse_of(campaign, run) -> Traverse:
    """The measured traverse of a terrain run of ``campaign`` (juno.campaign objects)."""
    from .campaign import read_run
    data = read_run(campaign, run)
    t, x = data.samples("pos_x")
    _, y = data.samples("pos_y")
    _, z = data.samples("pos_z")
    keep = t >= t[0] + SETTLING
    t, x, y, z = t[keep], x[keep], y[keep], z[keep]
    if data.has("yaw"):
        ty, yaw = data.samples("yaw")
        yaw = np.interp(t, ty, np.unwrap(yaw))
    else:   # heading from the track: the rover drives forwards
        yaw = np.unwrap(np.arctan2(np.gradient(y), np.gradient(x)))
    attitude = {}
    for name in ("pitch", "roll"):
        if data.has(name):
            ta, a = data.samples(name)
            attitude[name] = np.interp(t, ta, a)
    rover = campaign.rover or {}
    return Traverse(x, y, z, yaw, attitude.get("pitch"), float(rover.get("rover.wheelbase", DEFAULT_WHEELBASE)),
                    float(rover.get("rover.track", DEFAULT_TRACK)), roll=attitude.get("roll"))


def flat_height(campaign) -> float | None:
    """Mean measured chassis height (m) on the drawbar runs (flat ground at z = 0), or None."""
    from .campaign import read_run
    heights = []
    for run in campaign.runs_of_kind("drawbar"):
        data = read_run(campaign, run)
        t, z = data.samples("pos_z")
        heights.append(z[t >= t[0] + SETTLING])
    return float(np.mean(np.concatenate(heights))) if heights else None
