"""Registration of a LIDAR scan against a measured traverse, without simulating the rover.

A misregistered scan puts the terrain's features (the mound) in the wrong place, and the
rover's measured height, pitch and roll along its measured path show where they really are.
For a trial registration (offset o = (ox, oy) m, raise oz m, yaw psi rad, slopes ax and ay: grid
point q appears at o + Rz(psi) q, raised by oz + ax x + ay y at world (x, y), as the FMU's
``terrain.offset*`` and ``terrain.slope*`` parameters place it) the rover is posed on
the scanned ground at every measured position and heading: the chassis height z, roll, pitch
and rocker angle beta are solved so that each of the four wheels rests on the ground,

    hub_z,w(z, roll, pitch, beta) = W(hub_xy,w) + h0 - pivot height     (w = FL, RL, FR, RR)

with the FMU's geometry (rover.c: rocker pivots at +-track/2 beside the chassis reference
point, the hubs +-wheelbase/2 along each rocker and the pivot height below it, the rockers
turned by +beta and -beta by the differential), W the height at which a rigid wheel of the
FMU's radius, rolling along the heading, touches the gridded scan (the highest point of the
scan under the wheel's circle, less the radius), and h0 the chassis height above flat ground
(the mean measured height on the drawbar runs, which are on flat ground at z = 0: it carries
the wheel radius less the sinkage).  The residuals are the measured height, pitch and roll
against the posed rover's, pitch and roll scaled by the attitude gains a_p and a_r: nuisance
parameters, fitted with the offsets and then dropped.  The chassis tilts more than the ground
between its wheels, because on a slope the load moves to the downhill wheels, which sink deeper
(at the true registration of 40 synthetic campaigns climbing the mound, a_p 1.10-1.19 and a_r
0.94-1.04).

Why the exact pose: a simpler model takes the ground directly below nominal wheel points, pitch
and roll as the slopes between them, and the height as their mean.  On the mound's 0.2-0.35
slopes a wheel of 0.28 m radius rests up to 1.6 cm above the point below its hub, the hubs sit
0.15 m below the pivots (so they move fore and aft as the chassis pitches), and the measured
angles are Euler angles of a tilted chassis, not slopes.  Measured at the true registration of
the same 40 campaigns (20 terrain_offset, 20 with nothing hidden; sensor noise 3 mm and 3 mrad),
the RMS model error was

    height 4.3-6.5 mm, pitch 6.5-11.7 mrad, roll 5.5-11.9 mrad    (simpler model)
    height 3.2-4.2 mm, pitch 5.9-9.8 mrad,  roll 3.6-8.6 mrad     (exact pose)

and the simpler model's fit spent that error on a sideways shift traded against a turn.  Over 20
fresh terrain_offset campaigns (strengths 0.7-1), the registration fitted on the whole run (the
exact pose) maps the measured path into the scan 2.3-18.2 cm (median 5.5 cm, 9 of 20 within
5 cm; the largest distance along the path) from where the true registration maps it: a shift
across the path and a turn still trade against each other where the path crosses the mound on
one side only.

About the path's centre: the search turns and tilts the scan about the centre of the measured
path's bounding box (turning_centre) and then shifts it, and only the result is expressed as the
FMU's parameters about the world origin (fmu_offsets).  A turn about the world origin moves a scan
that lies d metres from it by d times the angle, so with the shifts bounded (LIMITS) a scan far
from the origin could not be turned at all: searched about the origin, the same data in a total
station's frame set up 250 m away place the mound 3.6 cm from where a frame about the scan
places it.  About the path's centre the bounds, the starts and the result mean the same in every
frame (the mound within 1 mm; the rover is posed in a frame centred on the path, where the pose
solve keeps its precision in a map's coordinates too).

The tilt: a scan levelled by its instrument (a compensator, an IMU) is off by a fraction of a
degree, and over a test area of 10 m that raises its far side by centimetres against its near
side, which no shift or turn expresses.  To first order in the angle, a rotation about a
horizontal axis raises each point by the slope times its distance from the axis and moves it
sideways by its height times the angle (under 3 mm for the mound's 0.3 m at 0.5 degrees), so the
tilt is a plane added to the scan's heights.

Least squares over the shift, raise and turn and the two gains from a grid of starts gives the
registration without a tilt; the one with the tilt is searched from its optimum and from the same
starts (_fit).  The three registrations are nested (the scan as it is, untilted, tilted), and
register() keeps the tilt only if it explains the measurements EVIDENCE_RATIO times better than
the best simpler one they support (tilt_judged: the untilted registration where it is itself
EVIDENCE_RATIO times better than the scan as it is, else the scan as it is), and the registration
only if it explains them EVIDENCE_RATIO times better than the scan as it is.  Along a short path
a shift and a turn of a ridge take up part of a tilt, which leaves the untilted registration
halfway between the scan as it is and the tilted one: hence the tilt is not judged against the
untilted registration alone, nor searched only from its optimum.  held_out_evidence() fits it on
training samples only and
measures how much better it explains the held-out ones (HELD_OUT_RATIO): that is how the
diagnosis judges a misregistration.  No FMU is needed.

A registration belongs to a scan: each scan was taken and registered on its own, with its own
error.  scans_of() groups a campaign's terrain runs by the scan file they name; the runs on one
scan share its registration, fitted on all of them at once (their traverses joined), and no
other scan's data enters it (ScanEvidence, ScanRegistrations).

Assumptions, named: the sinkage is the same everywhere (it changes by millimetres with the
load transfer, which the attitude gains absorb); each wheel is a rigid circle in the vertical
plane of the chassis heading (the tyre's width and the wheel's lean with the chassis roll are
ignored); the rover is at rest in each pose (no dynamics: pitching oscillations and the
chassis's lag behind the ground are model error).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from .pointcloud import Grid
from .rover_model import rover

#: Trial offsets of the starting grid: shifts (m) in x and y, yaw (rad).
START_SHIFTS = (-0.3, -0.15, 0.0, 0.15, 0.3)
START_YAWS = (-0.06, -0.03, 0.0, 0.03, 0.06)
#: Weights: the height's and the pitch's typical model error (not the sensor noise: the chassis
#: does not follow the ground exactly), m and rad.
SIGMA_Z = 0.01
SIGMA_PITCH = 0.01
SIGMA_ROLL = 0.01
#: The registrations searched: shifts up to 0.6 m, raises up to 10 cm, turns up to 7 deg about
#: the measured path's centre (turning_centre), tilts up to 2 deg (slopes of 0.035 in x and y).  A
#: traverse that crosses no terrain feature leaves the registration undetermined, and an
#: unbounded search then wanders (a 2 m, 29 deg "registration" was found on such a run).  The
#: tilt's bound: a scan levelled by its instrument's compensator or an IMU is off by well under a
#: degree; twice that leaves the search room without letting a tilt stand in for the mound's
#: flanks.
LIMITS = np.array([0.6, 0.6, 0.1, 0.12, 0.035, 0.035])
#: Registration parameters: shift x, shift y, raise (m), turn (rad), slope in x, slope in y.
NOFFSETS = len(LIMITS)
#: How much better than the unshifted scan a registration must explain the measurements (ratio
#: of the two least-squares costs, each with its best attitude gains) to be taken as evidence of
#: a misregistration.  The kinematic model's own error leaves room for any registration to
#: improve a little: on 20 synthetic campaigns with nothing misregistered the ratio was 1.10-2.58
#: with the simpler kinematic model (module docstring), and in the detection studies such small
#: registrations were named as false causes by the terrain replay (which a 5 cm move of the mound
#: can change by half): 2 of those 20 campaigns without the attitude gains, 1 with them (ratio 1.10).  Set
#: from that null distribution (1.5 times its largest value), not from the misregistered
#: campaigns (ratios 5.3-74).  With the exact pose: 1.06-1.52 on those 20, 1.02-1.59 on 80 with
#: a soil effect that leaves the sinkage uniform, 1.18-8.71 on 20 with a weak soil patch (over 4
#: on two: the patch's deeper sinkage looks like a lower scan), 8.4-173 on 20 misregistered.
EVIDENCE_RATIO = 4.0
#: Bounds of the attitude gains, (lower, upper) for pitch, then roll: the chassis tilts by
#: 0.7-1.5 times the posed rover's pitch, and by 0.9-1.1 times its roll (measured at the true
#: registration of 40 synthetic campaigns: 1.10-1.19 in pitch, 0.94-1.04 in roll).  Assumption,
#: named: across the 1.35 m track the load moves little on a side slope, so the downhill wheels
#: sink only millimetres deeper.  Why bounded so: a free roll gain trades against a turn of the
#: scan; with the roll gain free down to 0.7, one of 20 terrain_offset campaigns took 0.76 and a
#: turn 0.05 rad off, which put the mound's flanks 14 cm from where they are (7 cm so bounded; the
#: bound moved the mound of the other 19 registrations by under 1 cm).
GAIN_LIMITS = ((0.7, 1.5), (0.9, 1.1))


@dataclass(frozen=True)
class Traverse:
    """A measured terrain run at the total station's sample times: position (m), yaw, pitch
    and roll (rad, interpolated from the IMU), and the rover's geometry (m): wheelbase and track
    (between wheel centres), the rocker pivots' height above the axles, the wheel radius.
    ``pivot_height`` and ``wheel_radius`` not given are the FMU's (juno.rover_model)."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    yaw: np.ndarray
    pitch: np.ndarray | None
    wheelbase: float
    track: float
    roll: np.ndarray | None = None
    pivot_height: float | None = None     # None: the FMU's, filled in on construction
    wheel_radius: float | None = None     # None: the FMU's, filled in on construction
    #: sample times (s), where known: they say which samples fall in which held-out block
    t: np.ndarray | None = None

    def __post_init__(self):
        if self.pivot_height is None or self.wheel_radius is None:
            fmu = rover()
            if self.pivot_height is None:
                object.__setattr__(self, "pivot_height", fmu.pivot_height)
            if self.wheel_radius is None:
                object.__setattr__(self, "wheel_radius", fmu.wheel_radius)

    def subset(self, keep: np.ndarray) -> "Traverse":
        """The samples where ``keep`` (boolean, one per sample) is true."""
        def cut(a):
            return None if a is None else a[keep]
        return replace(self, x=self.x[keep], y=self.y[keep], z=self.z[keep], yaw=self.yaw[keep],
                       pitch=cut(self.pitch), roll=cut(self.roll), t=cut(self.t))


#: Points across a wheel's circle (fractions of its radius) where the scan is sampled to find
#: the height at which the wheel touches it.
ENVELOPE_POINTS = np.linspace(-1.0, 1.0, 13) * 0.999
#: The pose solve stops when every wheel rests on the ground to this (m), or after POSE_ITERATIONS
#: (the registration's finite-difference steps of 1e-6 move the residuals by about 3e-4 of their
#: sigma, so this leaves the differences exact to 0.1 %).
POSE_TOLERANCE = 1e-10
POSE_ITERATIONS = 30
#: Step (of z in m, of the angles in rad) of the finite differences of the pose solve's Jacobian.
POSE_STEP = 1e-6
#: Wheel order of the pose arrays: FL, RL, FR, RR (the FMU's).  Side: +1 left, -1 right.
_SIDE = np.array([1.0, 1.0, -1.0, -1.0])
_FORE = np.array([1.0, -1.0, 1.0, -1.0])
#: Largest array of scan samples (envelope points x registrations x samples x wheels) one batch of
#: pose solves builds: registrations beyond it are solved in further batches.  Measured on a
#: traverse of 70 samples: a registration cost 3.9 ms of CPU solved alone, 2.3-2.5 ms in batches
#: of 4-16 (arrays of 15,000-60,000 elements), and 4-4.5 ms in batches of 32-128, whose arrays
#: no longer fit in the processor's cache.
BATCH_ELEMENTS = 2 ** 15
#: Registrations whose poses a _Posing keeps besides its latest batch.
KEPT_POSES = 16


@dataclass(frozen=True)
class _Frame:
    """The hubs of the rover in a pose (hub_positions), with the steps on the way that the pose
    solve's Jacobian reuses: the hub below the pivot in the chassis frame (x1, y1, z1, turned by
    the rocker), after the roll (y2, z2, with cos and sin of the roll), after the pitch (z3, with
    cos and sin of the pitch), and the world position (x, y, z), each (..., n, 4) (m)."""

    x1: np.ndarray
    y1: np.ndarray
    z1: np.ndarray
    cr: np.ndarray
    sr: np.ndarray
    y2: np.ndarray
    z2: np.ndarray
    cp: np.ndarray
    sp: np.ndarray
    z3: np.ndarray
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray


def _rocked(tr: Traverse, beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The hub's x and z (m) in the chassis frame for rocker angle ``beta`` (rad, (..., n, 1)):
    the rockers turned by +beta on the left and -beta on the right."""
    b = _SIDE * beta
    cb, sb = np.cos(b), np.sin(b)
    half = tr.wheelbase / 2
    return cb * _FORE * half - sb * tr.pivot_height, -sb * _FORE * half - cb * tr.pivot_height


def _frame(tr: Traverse, pose: np.ndarray, cy: np.ndarray, sy: np.ndarray) -> _Frame:
    """hub_positions with its steps; ``cy``, ``sy``: cos and sin of the traverse's yaw, (n, 1)."""
    z, roll, pitch, beta = (pose[..., i:i + 1] for i in range(4))
    x1, z1 = _rocked(tr, beta)
    y1 = np.broadcast_to(_SIDE * tr.track / 2, x1.shape)
    cr, sr = np.cos(roll), np.sin(roll)
    y2, z2 = cr * y1 - sr * z1, sr * y1 + cr * z1          # Rx(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    x3, z3 = cp * x1 + sp * z2, -sp * x1 + cp * z2         # Ry(pitch)
    return _Frame(x1, y1, z1, cr, sr, y2, z2, cp, sp, z3,
                  tr.x[:, None] + cy * x3 - sy * y2, tr.y[:, None] + sy * x3 + cy * y2, z + z3)


def hub_positions(tr: Traverse, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World x, y, z (m) of the four hubs, each of shape (n, 4) (FL, RL, FR, RR), for the chassis
    at the measured x, y and yaw with ``pose`` (n, 4) = (z m, roll, pitch, beta rad), as rover.c
    places them: pivot (0, +-track/2, 0) in the chassis frame, hub (+-wheelbase/2, 0, -pivot
    height) in the rocker frame, which is turned about the chassis y axis by +beta on the left and
    -beta on the right; the chassis rotation is Rz(yaw) Ry(pitch) Rx(roll).  ``pose`` may also be
    a stack (k, n, 4) of poses along the traverse; the results are then (k, n, 4)."""
    f = _frame(tr, pose, np.cos(tr.yaw)[:, None], np.sin(tr.yaw)[:, None])
    return f.x, f.y, f.z


def _hub_heights_moved(tr: Traverse, pose: np.ndarray, f: _Frame) -> list[np.ndarray]:
    """The hubs' heights (m, (..., n, 4)) with each coordinate of ``pose`` (z, roll, pitch, beta)
    in turn moved by POSE_STEP, from ``f``, the frame of ``pose``: each recomputes only what that
    coordinate changes, with the arithmetic of _frame."""
    z, roll, pitch, beta = (pose[..., i:i + 1] for i in range(4))
    cr, sr = np.cos(roll + POSE_STEP), np.sin(roll + POSE_STEP)
    cp, sp = np.cos(pitch + POSE_STEP), np.sin(pitch + POSE_STEP)
    x1, z1 = _rocked(tr, beta + POSE_STEP)
    z2 = f.sr * f.y1 + f.cr * z1
    return [(z + POSE_STEP) + f.z3,
            z + (-f.sp * f.x1 + f.cp * (sr * f.y1 + cr * f.z1)),
            z + (-sp * f.x1 + cp * f.z2),
            z + (-f.sp * x1 + f.cp * z2)]


class _Posing:
    """The rover posed along one traverse on one gridded scan, for trial registrations.

    What does not depend on the registration is computed once: the heading's cosine and sine, and
    the envelope points of a wheel along it.  The poses of the registrations solved last are kept
    (a least-squares fit evaluates one registration several times: the finite-difference steps of
    the attitude gains leave the registration as it is), and poses(), given the registrations a
    fit is about to try (a grid of starts, the steps of a finite-difference Jacobian), solves them
    at once, each as pose_on_ground would alone: every sample's arithmetic is elementwise, and
    each registration's Newton iteration stops by its own test."""

    def __init__(self, grid: Grid, tr: Traverse, h0: float):
        self.grid, self.tr, self.h0 = grid, tr, h0
        self.cy, self.sy = np.cos(tr.yaw)[:, None], np.sin(tr.yaw)[:, None]
        f = ENVELOPE_POINTS.reshape(-1, 1, 1, 1)
        radius = tr.wheel_radius
        # (points, 1, n, 1): the envelope points' world offsets from the hub along the heading
        self.along_x = (f[:, 0] * radius * self.cy)[:, None]
        self.along_y = (f[:, 0] * radius * self.sy)[:, None]
        self.drop = radius * (np.sqrt(1.0 - f * f) - 1.0)
        self._kept: dict[bytes, np.ndarray] = {}

    def ground(self, x: np.ndarray, y: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """wheel_ground for hubs at world (x, y), (k, n, m) (m), each of the k registrations
        ``offsets`` (k, NOFFSETS) for its own hubs."""
        ox, oy, oz, yaw, slope_x, slope_y = (offsets[:, i].reshape(-1, 1, 1) for i in range(NOFFSETS))
        c, s = np.cos(yaw), np.sin(yaw)
        dx, dy = x + self.along_x - ox, y + self.along_y - oy          # from the scan's origin
        samples = self.grid.height(c * dx + s * dy, -s * dx + c * dy) + self.drop
        # The highest sample, refined by the parabola through it and its neighbours: the samples are
        # R/6 apart, which alone leaves the height up to 1 mm low on a slope.
        top = np.argmax(samples, axis=0)
        k = np.clip(top, 1, len(ENVELOPE_POINTS) - 2)
        flat, m = samples.reshape(-1), top.size               # point p of column j at p * m + j
        at = k.reshape(-1) * m + np.arange(m)
        before, best, after = (flat.take(at + d * m).reshape(k.shape) for d in (-1, 0, 1))
        curvature = before - 2.0 * best + after
        inside = (top == k) & (curvature < 0.0)
        vertex = best - (after - before) ** 2 / (8.0 * np.where(inside, curvature, -1.0))
        ground = np.where(inside, vertex, samples.max(axis=0)) + oz
        if np.any(slope_x != 0.0) or np.any(slope_y != 0.0):
            # The tilt raises the ground by a plane through the frame's origin; at the hub, not at
            # the touching point (under a degree of tilt moves it by well under a millimetre).
            ground = ground + (slope_x * x + slope_y * y)
        return ground

    def solve(self, offsets: np.ndarray) -> np.ndarray:
        """The poses (k, n, 4) for registrations ``offsets`` (k, NOFFSETS) (pose_on_ground's Newton
        iteration, each registration's stopping on its own)."""
        tr, h0 = self.tr, self.h0
        clearance = h0 - tr.pivot_height          # hub height above the ground it rests on
        q = np.zeros((len(offsets), len(tr.x), 4))
        q[..., 0] = h0 + self.ground(tr.x[None, :, None], tr.y[None, :, None], offsets)[..., 0]
        active = np.arange(len(offsets))
        for _ in range(POSE_ITERATIONS):
            pose = q[active]
            f = _frame(tr, pose, self.cy, self.sy)
            gap = f.z - (self.ground(f.x, f.y, offsets[active]) + clearance)
            going = ~(np.max(np.abs(gap), axis=(1, 2)) < POSE_TOLERANCE)
            if not going.all():
                if not going.any():
                    break
                active, pose, gap = active[going], pose[going], gap[going]
                f = _frame(tr, pose, self.cy, self.sy)
            jac = np.stack([(moved - f.z) / POSE_STEP for moved in _hub_heights_moved(tr, pose, f)], axis=-1)
            q[active] = pose - np.linalg.solve(jac, gap[..., None])[..., 0]
        return q

    def poses(self, offsets: list[np.ndarray]) -> list[np.ndarray]:
        """The pose (n, 4) for each registration of ``offsets`` (each (NOFFSETS,)): kept ones as kept, the
        others solved together (in batches of BATCH_ELEMENTS) and kept."""
        keys = [_full(o).tobytes() for o in offsets]
        new = list(dict.fromkeys(k for k in keys if k not in self._kept))
        per = max(1, BATCH_ELEMENTS // (len(ENVELOPE_POINTS) * 4 * max(len(self.tr.x), 1)))
        for i in range(0, len(new), per):
            batch = new[i:i + per]
            for key, pose in zip(batch, self.solve(np.array([np.frombuffer(k) for k in batch]))):
                self._kept[key] = pose
        found = [self._kept[k] for k in keys]
        for key in list(self._kept)[:max(0, len(self._kept) - KEPT_POSES - len(new))]:
            del self._kept[key]
        return found

    def residuals(self, offset: np.ndarray, gains: tuple[float, float]) -> np.ndarray:
        """residuals() of the traverse for registration ``offset`` (NOFFSETS,)."""
        return _scaled(self.tr, self.poses([offset])[0], gains)


def wheel_ground(grid: Grid, tr: Traverse, x: np.ndarray, y: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """The ground height (m) a wheel with its hub above world (x, y) ((n, m), n the traverse's
    samples) rests on, for registration ``offset`` (ox, oy, oz, yaw, slope x, slope y): the highest point of the
    scan under the wheel's circle (radius tr.wheel_radius, in the vertical plane of the chassis
    heading), less the radius.  On flat ground it is the ground; on a 0.3 slope, 1.2 cm above the
    point below the hub."""
    offsets = _full(offset).reshape(1, NOFFSETS)
    return _Posing(grid, tr, 0.0).ground(np.asarray(x, dtype=float)[None], np.asarray(y, dtype=float)[None],
                                         offsets)[0]


def pose_on_ground(grid: Grid, tr: Traverse, offset: np.ndarray, h0: float) -> np.ndarray:
    """The rover's pose (n, 4): chassis height z (m), roll, pitch (rad, the FMU's conventions:
    roll positive left side up, pitch positive nose down) and rocker angle beta (rad), with all
    four wheels resting on the scanned ground (registered by ``offset``) at the measured x, y and
    yaw; h0 is the chassis height above flat ground.  Newton's method with the Jacobian of the
    hub heights with the ground held (the hubs move sideways by millimetres per iteration, so it
    converges by a factor of about ten an iteration)."""
    return _Posing(grid, tr, h0).solve(_full(offset).reshape(1, NOFFSETS))[0]


def _full(offset) -> np.ndarray:
    """A registration as NOFFSETS numbers: one of four (shift, raise, turn) is untilted."""
    o = np.asarray(offset, dtype=float).reshape(-1)
    return np.concatenate([o, np.zeros(NOFFSETS - len(o))]) if len(o) < NOFFSETS else o


def _scaled(tr: Traverse, pose: np.ndarray, gains: tuple[float, float]) -> np.ndarray:
    """The scaled residuals (residuals()) of the rover posed so (n, 4)."""
    r = [(tr.z - pose[:, 0]) / SIGMA_Z]
    if tr.pitch is not None:
        r.append((tr.pitch - gains[0] * pose[:, 2]) / SIGMA_PITCH)
    if tr.roll is not None:
        r.append((tr.roll - gains[1] * pose[:, 1]) / SIGMA_ROLL)
    return np.concatenate(r)


def residuals(offset: np.ndarray, grid: Grid, tr: Traverse, h0: float,
              gains: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """Scaled residuals of height (and pitch and roll, if measured) for a trial registration,
    with the chassis tilting ``gains`` (pitch, roll) times the posed rover's attitude."""
    return _scaled(tr, pose_on_ground(grid, tr, offset, h0), gains)


@dataclass(frozen=True)
class _Fitted:
    """A registration's least squares (_fit): the registration without a tilt and, refined from
    it, the one with (each the NOFFSETS FMU parameters then the two attitude gains, and its
    cost), and the gains alone with the scan as it is (and their cost)."""

    untilted: np.ndarray
    cost: float
    tilted: np.ndarray
    cost_tilted: float
    gains_as_scanned: np.ndarray
    cost_as_scanned: float


def _fit(grid: Grid, tr: Traverse, h0: float | None) -> _Fitted:
    """Least squares of the registration without a tilt and the two attitude gains from a grid of
    starts, then of every parameter with the tilt from that optimum and from the grid's best
    starts (the best kept), and of the gains alone with the scan as it is.  With ``h0`` None the
    raise is not fitted (see register)."""
    fit_z = h0 is not None
    # Posed in a frame centred on the path: a registration about its origin is one about the
    # path's centre, and the pose solve keeps its precision in a map's coordinates (millions of
    # metres leave it nanometres, where it iterates to a tenth of one).
    centre = turning_centre(tr)
    posing = _Posing(replace(grid, x0=grid.x0 - centre[0], y0=grid.y0 - centre[1]),
                     replace(tr, x=tr.x - centre[0], y=tr.y - centre[1]), 0.0 if h0 is None else h0)

    def offset_of(v: np.ndarray) -> np.ndarray:
        """v: the shift, raise, turn and tilt about the traverse's centre, then the pitch and roll
        gains; returned as the registration in the path-centred frame."""
        return np.array([v[0], v[1], v[2] if fit_z else 0.0, v[3], v[4], v[5]])

    def res(v: np.ndarray) -> np.ndarray:
        r = posing.residuals(offset_of(v), (v[6], v[7]))
        if not fit_z:
            r[:len(tr.z)] -= np.mean(r[:len(tr.z)])   # the height offset is free
        return r

    lower = np.concatenate([-LIMITS, [g[0] for g in GAIN_LIMITS]])
    upper = np.concatenate([LIMITS, [g[1] for g in GAIN_LIMITS]])
    scale = np.array([0.1, 0.1, 0.01, 0.02, 0.005, 0.005, 0.1, 0.1])

    def search(free: np.ndarray, starts: list[np.ndarray], base: np.ndarray):
        """Least squares over v[free] (the others as in ``base``) from each of ``starts``; the best."""
        def full(u: np.ndarray) -> np.ndarray:
            v = base.copy()
            v[free] = u
            return v

        def each(fun, points) -> list[np.ndarray]:
            """``fun`` at each of ``points`` with their registrations posed at once: the starts,
            and the steps of least_squares' finite-difference Jacobian (its ``workers``)."""
            points = list(points)
            posing.poses([offset_of(full(u)) for u in points])
            return [fun(u) for u in points]

        best = None
        for start in starts:
            fit = least_squares(lambda u: res(full(u)), np.clip(start[free], lower[free], upper[free]),
                                x_scale=scale[free], max_nfev=300, diff_step=1e-6,
                                bounds=(lower[free], upper[free]), workers=each)
            if best is None or fit.cost < best.cost:
                best = fit
        return full(best.x), float(best.cost)

    untilted_free = np.array([0, 1, 2, 3, NOFFSETS, NOFFSETS + 1])
    grid_starts = [np.array([dx, dy, 0.0, yaw, 0.0, 0.0, 1.0, 1.0])
                   for dx in START_SHIFTS for dy in START_SHIFTS for yaw in START_YAWS]
    posing.poses([offset_of(v) for v in grid_starts])
    costs = [float(np.sum(res(v) ** 2)) for v in grid_starts]
    best_starts = [grid_starts[i] for i in np.argsort(costs)[:4]]
    untilted, cost = search(untilted_free, best_starts, np.zeros(NOFFSETS + 2))
    # The tilted registration is searched from the untilted optimum and from the same starts: where
    # a shift and a turn take up part of a tilt, the untilted optimum lies in their basin, and a
    # search from there alone keeps the shift and turn that stood in for the tilt.
    tilted, cost_tilted = search(np.arange(NOFFSETS + 2), [untilted] + best_starts, untilted)
    g = slice(NOFFSETS, NOFFSETS + 2)
    as_scanned = least_squares(lambda gains: res(np.concatenate([np.zeros(NOFFSETS), gains])),
                               np.clip(np.ones(2), lower[g], upper[g]), bounds=(lower[g], upper[g]))
    for v in (untilted, tilted):
        v[:NOFFSETS] = fmu_offsets(offset_of(v), centre)
    return _Fitted(untilted, cost, tilted, cost_tilted, as_scanned.x, float(as_scanned.cost))


def turning_centre(tr: Traverse) -> np.ndarray:
    """The point (x, y, m) a registration of ``tr`` is searched about: the centre of the
    measured path's bounding box (module docstring, "About the path's centre")."""
    return np.array([0.5 * (float(np.min(tr.x)) + float(np.max(tr.x))),
                     0.5 * (float(np.min(tr.y)) + float(np.max(tr.y)))])


def fmu_offsets(about_centre: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """The FMU's registration (ox, oy, oz, yaw, ax, ay: grid point q at world o + Rz(yaw) q,
    raised by oz + ax x + ay y at world (x, y)) of the one ``about_centre`` = (sx, sy, rz, yaw,
    ax, ay) that turns the grid by yaw about ``centre`` (x, y, m), shifts it by (sx, sy) and raises
    it by rz + ax (x - cx) + ay (y - cy): o = s + centre - Rz(yaw) centre, oz = rz - ax cx - ay cy."""
    sx, sy, rz, yaw, ax, ay = (float(a) for a in about_centre)
    c, sn = np.cos(yaw), np.sin(yaw)
    cx, cy = float(centre[0]), float(centre[1])
    return np.array([sx + (cx - (c * cx - sn * cy)), sy + (cy - (sn * cx + c * cy)), rz - (ax * cx + ay * cy),
                     yaw, ax, ay])


#: The FMU's registration parameters, in the order of a registration's numbers.
OFFSET_NAMES = ("terrain.offsetX", "terrain.offsetY", "terrain.offsetZ", "terrain.offsetYaw",
                "terrain.slopeX", "terrain.slopeY")


def _offsets(x: np.ndarray) -> dict[str, float]:
    return {name: float(x[i]) for i, name in enumerate(OFFSET_NAMES)}


def register(grid: Grid, tr: Traverse, h0: float | None) -> dict[str, float]:
    """The registration (FMU names ``terrain.offsetX/Y/Z/Yaw``, ``terrain.slopeX/Y``) that best explain the
    measured height, pitch and roll, or all 0 (the scan as it is) unless they explain them
    EVIDENCE_RATIO times better than the scan as it is.  With ``h0`` None (no flat-ground run to
    measure the chassis height on), the raise cannot be told from the chassis height and is left
    at 0.  Whether that registration is tilted: tilt_judged, at the same ratio."""
    fitted = _fit(grid, tr, h0)
    x, cost = fitted.untilted, fitted.cost
    if tilt_judged(fitted.cost_as_scanned, fitted.cost, fitted.cost_tilted, EVIDENCE_RATIO):
        x, cost = fitted.tilted, fitted.cost_tilted
    if not fitted.cost_as_scanned >= EVIDENCE_RATIO * cost:
        x = np.zeros(NOFFSETS)
    return _offsets(x)


def tilt_judged(as_scanned: float, untilted: float, tilted: float, ratio: float) -> bool:
    """Whether the registration judged against the scan as it is is the tilted one, from how well
    each of the three nested registrations explains the measurements (``as_scanned``: the scan as
    it is; ``untilted``: shifted, raised and turned; ``tilted``: also tilted; each a cost or a mean
    square, lower better).  The untilted registration is judged where it explains them ``ratio``
    times better than the scan as it is and the tilted one does not explain them ``ratio`` times
    better than it; otherwise the tilted one is.  So the tilt is judged against the best simpler
    registration the measurements support: the untilted one where they support it, else the scan
    as it is.  The scan is misregistered when the registration judged explains the measurements
    ``ratio`` times better than the scan as it is.

    Why not always against the untilted registration: along a short path a shift and a turn take
    up part of a tilt (a turned ridge raises the ground along the path as a plane does), so a
    tilted scan can leave the untilted registration halfway, neither it against the scan as it is
    nor the tilt against it reaching ``ratio``, though the tilted registration explains the
    measurements many times better than the scan as it is.  Judged only against the untilted one,
    the tilt would be dropped and the scan, judged by what remains, found in its place.  Where the
    untilted registration is supported, the tilt is one more step and must earn its place
    against it."""
    untilted_supported = as_scanned >= ratio * untilted
    return bool(not untilted_supported or untilted >= ratio * tilted)


#: How much better than the scan as it is a registration fitted on the training samples must
#: explain the held-out samples (ratio of their mean squared scaled residuals of height, pitch
#: and roll, each with the attitude gains fitted on the training samples) to count as evidence
#: of a misregistration.  Measured on 20 synthetic campaigns of each kind (blocks of 4 s):
#: 0.61-1.36 with nothing hidden, 0.54-1.50 with multi-pass, slip-sinkage or a grouser,
#: 6.5-158 misregistered; 3.0 is near the geometric middle of 1.5 and 6.5 (measured with the
#: roll gain free to 0.7-1.5).  A soft soil patch reached 9.8: its deeper
#: sinkage looks like a lowered scan, which this kinematic model cannot tell apart, so the
#: diagnosis uses the evidence in its first round only, where a soil patch outranks the
#: registration by its replayed gain; on top of another cause the replay judges (diagnose._judge).
HELD_OUT_RATIO = 3.0


class _HeldOutFigures:
    """The held-out figures of registration evidence, from its held-out mean squared scaled
    residuals as scanned and as registered: one scan's (HeldOutEvidence) and every scan's pooled
    (ScanRegistrations) alike."""

    held_out_ms_as_scanned: float
    held_out_ms_registered: float

    @property
    def ratio(self) -> float:
        """How many times better the registration explains the held-out samples."""
        return self.held_out_ms_as_scanned / max(self.held_out_ms_registered, 1e-300)

    @property
    def gain(self) -> float:
        """Relative held-out gain of the registration over the scan as it is."""
        return 1.0 - self.held_out_ms_registered / self.held_out_ms_as_scanned


@dataclass(frozen=True)
class HeldOutEvidence(_HeldOutFigures):
    """A registration fitted on the training samples of a traverse (``offsets``), judged on the
    held-out ones: the held-out mean squared scaled residual (height, pitch, roll) with the scan
    as it is and with that registration, and their ratio.  ``offsets_all``: once the evidence
    is significant, the registration fitted on every sample, the measurement to use (None
    otherwise: the scan stays as it is)."""

    offsets: dict[str, float]
    held_out_ms_as_scanned: float
    held_out_ms_registered: float
    offsets_all: dict[str, float] | None = None
    #: how many held-out samples (each a height, pitch and roll) the mean squares are over
    held_out_samples: int = 0
    #: whether the registration judged is the tilted one (tilt_judged with HELD_OUT_RATIO), and
    #: the held-out mean squares of the registrations without and with a tilt
    tilted: bool = False
    held_out_ms_untilted: float = float("nan")
    held_out_ms_tilted: float = float("nan")

    @property
    def significant(self) -> bool:
        return bool(self.ratio >= HELD_OUT_RATIO)


def held_out_evidence(grid: Grid, tr: Traverse, h0: float | None, train: np.ndarray) -> HeldOutEvidence:
    """The registration fitted on the samples where ``train`` is true, and how much better than
    the scan as it is it explains the others (the held-out samples, which the fit did not see).

    Why held out: any registration explains the samples it was fitted to a little better (eight
    free parameters against the kinematic model's own error); on samples it did not see, only a
    real misregistration keeps its gain.

    The tilt is judged by the same rule, one level down (tilt_judged): the registration with a
    tilt must explain the held-out samples HELD_OUT_RATIO times better than the best simpler one
    they support, the one without a tilt where that one is supported, else the scan as it is.  A free
    tilt takes up the kinematic model's own error in roll and height (on 6 synthetic campaigns
    with the scan shifted and turned, not tilted, it moved the mound's fitted place from 5-9 cm to
    4-22 cm from the truth, explaining the held-out pose at most 1.3 times better), so it has to
    earn its place against a supported untilted registration.  Where the untilted one is not
    supported, the tilted one is judged against the scan as it is, at the same ratio as any
    registration: so judged, the registration explained the held-out pose at most 2.05 times
    better than the scan as it is on 40 synthetic campaigns with nothing hidden (20 of each
    design), at most 2.92 on 36 with a soft soil patch or strip or slip-sinkage, and 3.0-12 times
    on 25 of 40 with the scan tilted by 0.7-1 degrees (1.0-2.9 on the other 15)."""
    train = np.asarray(train, dtype=bool)
    if train.shape != tr.x.shape:
        raise ValueError(f"held_out_evidence: the training mask has shape {train.shape}, "
                         f"the traverse {tr.x.shape[0]} samples")
    if train.all() or not train.any():
        raise ValueError("held_out_evidence: the traverse needs both training and held-out samples")
    training = tr.subset(train)
    fitted = _fit(grid, training, h0)
    x, tilted, gains = fitted.untilted, fitted.tilted, fitted.gains_as_scanned
    held_out = tr.subset(~train)
    h = 0.0 if h0 is None else h0

    def mean_square(offset: np.ndarray, g: np.ndarray) -> float:
        r = residuals(offset, grid, held_out, h, (float(g[0]), float(g[1])))
        if h0 is None:
            r[:len(held_out.z)] -= np.mean(r[:len(held_out.z)])
        return float(np.mean(r ** 2))

    as_scanned_ms = mean_square(np.zeros(NOFFSETS), gains)
    untilted_ms = mean_square(x[:NOFFSETS], x[NOFFSETS:])
    tilted_ms = mean_square(tilted[:NOFFSETS], tilted[NOFFSETS:])
    tilt = tilt_judged(as_scanned_ms, untilted_ms, tilted_ms, HELD_OUT_RATIO)
    if tilt:
        x = tilted
    evidence = HeldOutEvidence(_offsets(x), as_scanned_ms, tilted_ms if tilt else untilted_ms,
                               held_out_samples=len(held_out.x), tilted=tilt, held_out_ms_untilted=untilted_ms,
                               held_out_ms_tilted=tilted_ms)
    if not evidence.significant:
        return evidence
    # Where the scan is, once it is known to be misregistered, is measured on the whole run:
    # fitted on half the samples, the mound landed up to 15 cm from where the truth puts it on
    # 20 synthetic campaigns (within 9 cm fitted on all).
    whole = _fit(grid, tr, h0)
    return replace(evidence, offsets_all=_offsets(whole.tilted if tilt else whole.untilted))


SETTLING = 2.0   # s at the start of a run left out (the rover starts from rest)


def traverse_of(campaign, run) -> Traverse:
    """The measured traverse of a terrain run of ``campaign`` (juno.campaign objects)."""
    from .campaign import read_run
    from .heading import track_headings
    data = read_run(campaign, run)
    t, x = data.samples("pos_x")
    _, y = data.samples("pos_y")
    _, z = data.samples("pos_z")
    keep = t >= t[0] + SETTLING
    t, x, y, z = t[keep], x[keep], y[keep], z[keep]
    if data.has("yaw"):
        ty, yaw = data.samples("yaw")
        yaw = np.interp(t, ty, np.unwrap(yaw))
    else:   # heading from the track (juno.heading): the rover drives forwards and does not crab
        yaw = track_headings(t, x, y)
    attitude = {}
    for name in ("pitch", "roll"):
        if data.has(name):
            ta, a = data.samples(name)
            attitude[name] = np.interp(t, ta, a)
    geometry = rover(campaign.rover)
    return Traverse(x, y, z, yaw, attitude.get("pitch"), geometry.wheelbase, geometry.track,
                    roll=attitude.get("roll"), pivot_height=geometry.pivot_height,
                    wheel_radius=geometry.wheel_radius, t=t)


def flat_height(campaign) -> float | None:
    """Mean measured chassis height (m) on the drawbar runs (flat ground at z = 0), or None."""
    from .campaign import read_run
    heights = []
    for run in campaign.runs_of_kind("drawbar"):
        data = read_run(campaign, run)
        t, z = data.samples("pos_z")
        heights.append(z[t >= t[0] + SETTLING])
    return float(np.mean(np.concatenate(heights))) if heights else None


def joined(traverses: list[Traverse]) -> Traverse:
    """The traverses of several runs over one scan as one (their samples one after another): the
    registration poses the rover at every sample on its own, so runs join without a seam.  Pitch
    and roll are kept only where every run measured them (the residuals are one block per
    signal); the geometry is the first run's (one rover per campaign)."""
    if not traverses:
        raise ValueError("joined: no traverse to join")
    first = traverses[0]
    if len(traverses) == 1:
        return first

    def cat(name: str) -> np.ndarray | None:
        parts = [getattr(tr, name) for tr in traverses]
        return None if any(a is None for a in parts) else np.concatenate(parts)
    return replace(first, x=cat("x"), y=cat("y"), z=cat("z"), yaw=cat("yaw"), pitch=cat("pitch"),
                   roll=cat("roll"), t=cat("t"))


def scans_of(campaign) -> list[tuple[str, list]]:
    """The campaign's scans, each with the terrain runs on it (juno.campaign RunSpec, manifest
    order), in the order of their first run: runs naming one file (the same file however the
    manifest spells its path) share one scan.  Each scan is named as the manifest names it for its
    first run."""
    scans: dict[str, tuple[str, list]] = {}
    for run in campaign.runs_of_kind("terrain"):
        key = str(campaign.terrain_path(run).resolve())
        scans.setdefault(key, (run.terrain, []))[1].append(run)
    return list(scans.values())


@dataclass(frozen=True)
class ScanEvidence:
    """One scan's registration: the scan file (as the campaign's manifest names it), the terrain
    runs on it, and the held-out evidence of the registration fitted on their training samples
    (None when the runs are too short to hold both training and held-out samples)."""

    scan: str
    runs: tuple[str, ...]
    evidence: HeldOutEvidence | None

    @property
    def significant(self) -> bool:
        """Whether the pose shows this scan misregistered (HELD_OUT_RATIO on its own held-out
        samples)."""
        return self.evidence is not None and self.evidence.significant

    @property
    def offsets(self) -> dict[str, float]:
        """The registration applied to this scan: the one fitted on every sample of its runs once
        the evidence is significant, else the scan as it is (all 0)."""
        if self.significant:
            return dict(self.evidence.offsets_all)
        return _offsets(np.zeros(NOFFSETS))


@dataclass(frozen=True)
class ScanRegistrations(_HeldOutFigures):
    """Every scan's registration (ScanEvidence, the campaign's scans in order), at least one with
    evidence.  The scans are judged one by one, each on its own held-out samples; the campaign's
    figures pool them: the held-out mean squared scaled residual over every scan's held-out
    samples, as scanned and with each scan registered as fitted on its training samples (for one
    scan, that scan's own figures)."""

    scans: tuple[ScanEvidence, ...]

    def _tested(self) -> list[HeldOutEvidence]:
        return [s.evidence for s in self.scans if s.evidence is not None]

    def _pooled(self, name: str) -> float:
        tested = self._tested()
        total = sum(e.held_out_samples for e in tested)
        if len(tested) == 1 or total == 0:
            return float(np.mean([getattr(e, name) for e in tested]))
        return float(sum(e.held_out_samples / total * getattr(e, name) for e in tested))

    @property
    def held_out_ms_as_scanned(self) -> float:
        return self._pooled("held_out_ms_as_scanned")

    @property
    def held_out_ms_registered(self) -> float:
        return self._pooled("held_out_ms_registered")

    @property
    def significant(self) -> bool:
        """Whether some scan is misregistered (its own evidence significant)."""
        return any(s.significant for s in self.scans)

    def misregistered(self) -> list[ScanEvidence]:
        """The scans whose evidence is significant, in order."""
        return [s for s in self.scans if s.significant]
