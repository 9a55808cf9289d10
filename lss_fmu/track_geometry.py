"""Track geometry in Python, formula for formula the C code of `fmu_src/track.c`.

Every element has a start point c0, a start frame R0 = [t n b] (columns:
tangent, lateral-left, up) and a constant turn rate w (rad/m) in that frame:
    R(s) = R0 exp(sigma [w]x),   c(s) = c0 + R0 int_0^sigma exp(u [w]x) e_x du,
with sigma = s - s0, both in closed form (Rodrigues). Straights have w = 0;
vertical curves turn about the lateral axis; horizontal curves and spirals turn
about the world vertical at the incline they are entered with (a spiral is a
horizontal curve entered on an incline: a helix). The residual closure error is
removed from the position by a linear blend over arc length, as in C.

The element chain is built with scalar `math` in the same order of operations
as C (so it is the same to the last bit or nearly); frames at arc lengths are
evaluated vectorised with numpy. tests/test_track_c_vs_python.py holds the two
to 1e-9 m.

Also here: motor placement (as `place_motors` in C), level changes (see
`Track.inclined_runs`) and a diagnosis of a loop that does not close.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .layout_format import CURVE, DEG, KIND_NAMES, SPIRAL, STRAIGHT, VCURVE, LayoutError, LayoutSpec

PITCH = 1.25               # m, cart pitch
TOL_POS = 1e-3             # m, closure limit in position
TOL_ANG = 1e-4             # rad, closure limit in direction
MOTOR_LENGTH = 0.6         # m, default active length of one linear motor (drive.motor_length)
LEVEL_TOL = 1e-7           # rad: an incline below this counts as level


def _mul(A, B):
    return [A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j]
            for i in range(3) for j in range(3)]


def _mulv(M, v):
    return [M[0] * v[0] + M[1] * v[1] + M[2] * v[2],
            M[3] * v[0] + M[4] * v[1] + M[5] * v[2],
            M[6] * v[0] + M[7] * v[1] + M[8] * v[2]]


def _skew(u):
    return [0.0, -u[2], u[1], u[2], 0.0, -u[0], -u[1], u[0], 0.0]


def _local(k, u, sigma):
    """(Rl, pl) after arc length sigma at turn rate k about unit axis u (as C element_local)."""
    if k == 0.0:
        return [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], [sigma, 0.0, 0.0]
    th = k * sigma
    S, C1 = math.sin(th), 1.0 - math.cos(th)
    K = _skew(u)
    K2 = _mul(K, K)
    Rl = [(1.0 if i % 4 == 0 else 0.0) + S * K[i] + C1 * K2[i] for i in range(9)]
    a, b = C1 / k, sigma - S / k
    return Rl, [sigma + a * K[0] + b * K2[0], a * K[3] + b * K2[3], a * K[6] + b * K2[6]]


def _angle_between(A, B):
    tr = sum(A[j] * B[j] + A[3 + j] * B[3 + j] + A[6 + j] * B[6 + j] for j in range(3))
    c = min(1.0, max(-1.0, 0.5 * (tr - 1.0)))
    f2 = sum((A[i] - B[i]) ** 2 for i in range(9))
    small = 2.0 * math.asin(min(1.0, math.sqrt(f2 / 8.0)))
    return small if c > 0.99 else math.acos(c)


@dataclass
class Run:
    """A maximal run of inclined track: elements first..last (indices, cyclic)."""
    first: int
    last: int
    s0: float
    s1: float              # may exceed the track length when the run wraps
    rise: float
    spiral: bool           # contains a spiral element: not a level change
    lines: tuple           # file lines of its first and last element


class Track:
    """A closed track built from a LayoutSpec (raises LayoutError as C's track_build fails)."""

    def __init__(self, spec: LayoutSpec, motor_length: float = MOTOR_LENGTH,
                 tol_pos: float = TOL_POS, tol_ang: float = TOL_ANG, check: bool = True):
        self.spec = spec
        els = spec.elements
        if not els:
            raise LayoutError("the layout has no track elements", None, spec.source)
        n = len(els)
        self.n = n
        self.kind = np.array([e.kind for e in els])
        self.lines = [e.line for e in els]
        s0, lengths, c0s, R0s, ws, ks, us = [], [], [], [], [], [], []
        self.entry_incline = []
        c = list(map(float, spec.start))
        ch, sh = math.cos(spec.heading), math.sin(spec.heading)
        Rstart = [ch, -sh, 0.0, sh, ch, 0.0, 0.0, 0.0, 1.0]
        R = list(Rstart)
        s = 0.0
        for e in els:
            s0.append(s)
            c0s.append(list(c))
            R0s.append(list(R))
            incline = math.asin(max(-1.0, min(1.0, R[6])))
            self.entry_incline.append(incline)
            if e.kind == STRAIGHT:
                if not e.length > 0:
                    self._fail(e, f"straight length must be positive, got {e.length:g}")
                length, w = e.length, [0.0, 0.0, 0.0]
            elif e.kind == VCURVE:
                if not (e.radius > 0 and e.angle != 0):
                    self._fail(e, f"vcurve needs a positive radius and a non-zero angle "
                                  f"(got {e.radius:g}, {e.angle:g})")
                length = e.radius * abs(e.angle)
                w = [0.0, -e.angle / length, 0.0]
            elif e.kind in (CURVE, SPIRAL):
                if not (e.radius > 0 and e.angle != 0):
                    self._fail(e, f"{KIND_NAMES[e.kind]} needs a positive radius and a non-zero sweep "
                                  f"(got {e.radius:g}, {e.angle:g})")
                cg = math.cos(incline)
                if cg < 1e-3:
                    self._fail(e, "a horizontal curve cannot start on vertical track")
                length = e.radius * abs(e.angle) / cg
                om = e.angle / length
                w = [om * R[6], om * R[7], om * R[8]]
                if e.kind == SPIRAL and e.has_rise:
                    rise = e.radius * abs(e.angle) * math.tan(incline)
                    if abs(rise - e.rise) > 1e-3:
                        need = math.atan2(e.rise, e.radius * abs(e.angle))
                        self._fail(e, "spiral rise %.4g m needs an entry incline of %.6g deg, "
                                      "the track arrives at %.6g deg (rise would be %.4g m)"
                                   % (e.rise, need * 180 / math.pi, incline * 180 / math.pi, rise))
            else:
                self._fail(e, f"unknown element kind {e.kind}")
            k = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
            u = [x * (1.0 / k) for x in w] if k > 0 else [0.0, 0.0, 0.0]
            Rl, pl = _local(k, u, length)
            d = _mulv(R, pl)
            c = [c[i] + d[i] for i in range(3)]
            R = _mul(R, Rl)
            lengths.append(length)
            ws.append(w)
            ks.append(k)
            us.append(u)
            s += length
        self.length = s
        self.s0 = np.array(s0)
        self.el_length = np.array(lengths)
        self.c0 = np.array(c0s)
        self.R0 = np.array(R0s).reshape(n, 3, 3)
        self.w = np.array(ws)
        self.k = np.array(ks)
        self.u = np.array(us)
        K = np.array([_skew(x) for x in us]).reshape(n, 3, 3)
        self._K, self._K2 = K, K @ K
        self.end = (np.array(c), np.array(R).reshape(3, 3))
        self.closure = np.array([c[i] - float(spec.start[i]) for i in range(3)])
        self.closure_angle = _angle_between(R, Rstart)
        self.closure_error = float(math.sqrt(sum(x * x for x in self.closure)))
        self.closes = self.closure_error <= tol_pos and self.closure_angle <= tol_ang
        if check and not self.closes:
            msg = ("the loop does not close: end point misses the start by %.6g m "
                   "(dx %.4g, dy %.4g, dz %.4g) and the direction by %.6g mrad "
                   "(limits %.3g m, %.3g mrad)"
                   % (self.closure_error, *self.closure, self.closure_angle * 1e3, tol_pos, tol_ang * 1e3))
            hint, line = self.diagnose()
            raise LayoutError(msg + (f"; {hint}" if hint else ""), line, spec.source) from None
        self.motors = self._place_motors(spec.n_motors, motor_length)

    # --- construction helpers ------------------------------------------------------
    def _fail(self, e, message):
        raise LayoutError(message, e.line or None, self.spec.source)

    def _place_motors(self, n_motors: int, motor_length: float) -> np.ndarray:
        if n_motors <= 0:
            return np.zeros((0, 2))
        S = 0.0
        for i in range(self.n):
            if self.kind[i] == STRAIGHT:
                S += self.el_length[i]
        if S <= 0:
            raise LayoutError(f"the layout asks for {n_motors} linear motors but has no straight track",
                              None, self.spec.source)
        out = np.zeros((n_motors, 2))
        el, acc = 0, 0.0
        for m in range(n_motors):
            u = (m + 0.5) * S / n_motors
            while el < self.n and (self.kind[el] != STRAIGHT or acc + self.el_length[el] < u):
                if self.kind[el] == STRAIGHT:
                    acc += self.el_length[el]
                el += 1
            el = min(el, self.n - 1)
            s0, le = float(self.s0[el]), float(self.el_length[el])
            half = 0.5 * min(motor_length, le)
            centre = s0 + (u - acc)
            if centre - half < s0:
                centre = s0 + half
            if centre + half > s0 + le:
                centre = s0 + le - half
            out[m] = (centre - half, centre + half)
        return out

    # --- evaluation ----------------------------------------------------------------
    def wrap(self, s) -> np.ndarray:
        s = np.array(s, dtype=float, ndmin=1)
        bad = ~((s >= 0) & (s < self.length))
        if bad.any():
            t = np.fmod(s[bad], self.length)
            t = np.where(t < 0, t + self.length, t)
            s[bad] = np.where(t >= self.length, 0.0, t)
        return s

    def element_at(self, s) -> np.ndarray:
        s = self.wrap(s)
        return np.clip(np.searchsorted(self.s0, s, side="right") - 1, 0, self.n - 1)

    def frame(self, s):
        """(c, R, w, el) at arc lengths s: positions (N,3), frames (N,3,3) with
        columns t n b, turn rates in the frame (N,3) rad/m, element indices (N,)."""
        s = self.wrap(s)
        i = np.clip(np.searchsorted(self.s0, s, side="right") - 1, 0, self.n - 1)
        sigma = s - self.s0[i]
        k = self.k[i]
        turning = k > 0
        ks = np.where(turning, k, 1.0)
        th = k * sigma
        S, C1 = np.sin(th), 1.0 - np.cos(th)
        K, K2 = self._K[i], self._K2[i]
        Rl = np.eye(3) + S[:, None, None] * K + C1[:, None, None] * K2
        a = np.where(turning, C1 / ks, 0.0)
        b = np.where(turning, sigma - S / ks, 0.0)
        pl = np.stack([sigma + a * K[:, 0, 0] + b * K2[:, 0, 0],
                       a * K[:, 1, 0] + b * K2[:, 1, 0],
                       a * K[:, 2, 0] + b * K2[:, 2, 0]], axis=1)
        R0 = self.R0[i]
        c = self.c0[i] + np.einsum("nij,nj->ni", R0, pl)
        c = c + (-s / self.length)[:, None] * self.closure[None, :]
        R = np.einsum("nij,njk->nik", R0, Rl)
        return c, R, self.w[i], i

    def position(self, s) -> np.ndarray:
        return self.frame(s)[0]

    def incline(self, s) -> np.ndarray:
        """Incline of the tangent, rad (+ climbing)."""
        R = self.frame(s)[1]
        return np.arcsin(np.clip(R[:, 2, 0], -1.0, 1.0))

    def curvature(self, s):
        """(heading rate, incline rate) in rad/m: d(heading)/ds about the world
        vertical (+ left; cos(incline)/R in a curve or spiral of horizontal
        radius R) and d(incline)/ds (+ climbing; 1/R in a vertical curve)."""
        _, R, w, _ = self.frame(s)
        return np.einsum("nij,nj->ni", R, w)[:, 2], -w[:, 1]

    def boundaries(self) -> np.ndarray:
        return np.append(self.s0, self.length)

    def sample(self, ds: float = 0.05) -> np.ndarray:
        """Arc lengths every ds plus every element boundary (both sides)."""
        n = max(2, int(math.ceil(self.length / ds)))
        s = np.linspace(0.0, self.length, n + 1)[:-1]
        eps = 1e-9
        return np.unique(np.concatenate([s, self.s0, np.maximum(self.s0[1:] - eps, 0.0),
                                         [self.length - eps]]))

    # --- derived quantities --------------------------------------------------------
    @property
    def n_carts(self) -> int:
        return self.spec.n_carts or int(math.floor(self.length / PITCH + 0.5))

    def _is_level(self, incline: float) -> bool:
        return abs(incline) <= LEVEL_TOL

    def inclined_runs(self) -> list:
        """Maximal runs of inclined track, split at every element boundary where
        the track is level. A run holding a spiral element is a spiral (it
        brings the track back to its level); every other run is a level change.
        A loop inclined everywhere is a single run."""
        n = self.n
        inclined = [self.kind[j] == VCURVE or not self._is_level(self.entry_incline[j]) for j in range(n)]
        level_at = [self._is_level(self.entry_incline[j]) for j in range(n)]
        if not any(inclined):
            return []
        start = next((j for j in range(n) if level_at[j]), 0)
        runs, cur = [], []
        for step in range(n):
            j = (start + step) % n
            if level_at[j] and cur:
                runs.append(cur)
                cur = []
            if inclined[j]:
                cur.append(j)
        if cur:
            runs.append(cur)
        out = []
        for r in runs:
            a, b = r[0], r[-1]
            s0 = float(self.s0[a])
            s1 = float(self.s0[b] + self.el_length[b])
            if s1 <= s0:
                s1 += self.length
            # rise from the element chain itself (before the closure blend)
            z1 = self.c0[b + 1][2] if b + 1 < n else self.end[0][2]
            out.append(Run(a, b, s0, s1, float(z1 - self.c0[a][2]), any(self.kind[j] == SPIRAL for j in r),
                           (self.lines[a], self.lines[b])))
        return out

    @property
    def n_level_changes(self) -> int:
        return sum(not r.spiral for r in self.inclined_runs())

    @property
    def n_spirals(self) -> int:
        return sum(r.spiral for r in self.inclined_runs())

    # --- what went wrong ---------------------------------------------------------
    def diagnose(self):
        """(hint, line) for a loop that does not close: the heading and incline
        budgets, the level changes that do not cancel, or the straight whose
        length would close the gap. line is None when no element is to blame."""
        els = self.spec.elements
        sweep = sum(e.angle for e in els if e.kind in (CURVE, SPIRAL)) / DEG
        turns = round(sweep / 360.0)
        vsum = sum(e.angle for e in els if e.kind == VCURVE) / DEG
        if self.closure_angle > TOL_ANG:
            parts = []
            if abs(vsum) > 1e-6:
                # the last vcurve after which the cumulative angle stays off zero
                acc, culprit = 0.0, None
                for e in els:
                    if e.kind == VCURVE:
                        before = acc
                        acc += e.angle / DEG
                        if abs(before) <= 1e-6:
                            culprit = e
                line = culprit.line if culprit else None
                parts.append(f"the vcurve angles add up to {vsum:+.6g} deg, so the track ends inclined"
                             + (f" (the climb from line {line} is never undone)" if line else ""))
            else:
                line = None
            miss = sweep - 360.0 * turns
            if abs(miss) > 1e-6 or turns == 0:
                parts.append(f"the horizontal sweeps add up to {sweep:.6g} deg "
                             f"(a loop needs +-360 deg): the heading misses by {miss:+.6g} deg")
            return "; ".join(parts) or None, line
        d = self.closure
        parts, line = [], None
        if abs(d[2]) > 1e-6:
            runs = self.inclined_runs()
            listed = ", ".join(f"lines {r.lines[0]}-{r.lines[1]} {r.rise:+.3f} m" for r in runs[:8])
            parts.append(f"the level changes do not cancel: the track ends {d[2]:+.4g} m off its start level"
                         + (f" ({listed}{', ...' if len(runs) > 8 else ''})" if runs else ""))
        dh = np.array([d[0], d[1], 0.0])
        horiz = float(np.linalg.norm(dh))
        if horiz > 1e-6:
            along = []  # level straights parallel to the gap
            for j in range(self.n):
                t = self.R0[j][:, 0]
                if self.kind[j] == STRAIGHT and abs(t[2]) <= 1e-9 and \
                        abs(float(np.dot(t, dh))) / horiz > 1 - 1e-6:
                    along.append(j)
            if along:
                amount = abs(float(np.dot(self.R0[along[0]][:, 0], dh)))

                def named(js):
                    ls = [els[j].line for j in js]
                    return (f"the straight at line {ls[0]}" if len(ls) == 1 else
                            "one of the straights at lines " + ", ".join(map(str, ls[:8]))
                            + (", ..." if len(ls) > 8 else ""))
                shorter = [j for j in along if float(np.dot(self.R0[j][:, 0], dh)) > 0]
                longer = [j for j in along if j not in shorter]
                line = els[along[0]].line
                fixes = ([f"shortening {named(shorter)}"] if shorter else []) + \
                        ([f"lengthening {named(longer)}"] if longer else [])
                parts.append(f"in plan the gap lies along the track: {' or '.join(fixes)} "
                             f"by {amount:.6g} m would close it")
            else:
                heading = math.degrees(math.atan2(d[1], d[0]))
                parts.append(f"in plan the end point lies {horiz:.4g} m away at a heading of {heading:.1f} deg; "
                             "no single level straight runs that way")
        return "; ".join(parts) or None, line
        d = self.closure
        parts, line = [], None
        if abs(d[2]) > 1e-6:
            runs = self.inclined_runs()
            listed = ", ".join(f"lines {r.lines[0]}-{r.lines[1]} {r.rise:+.3f} m" for r in runs[:8])
            parts.append(f"the level changes do not cancel: the track ends {d[2]:+.4g} m off its start level"
                         + (f" ({listed}{', ...' if len(runs) > 8 else ''})" if runs else ""))
        dh = np.array([d[0], d[1], 0.0])
        horiz = float(np.linalg.norm(dh))
        if horiz > 1e-6:
            best, best_cos = None, 0.0
            for j in range(self.n):
                t = self.R0[j][:, 0]
                if self.kind[j] != STRAIGHT or abs(t[2]) > 1e-9:
                    continue
                cosang = abs(float(np.dot(t, dh))) / horiz
                if cosang > best_cos:
                    best, best_cos = j, cosang
            if best is not None and best_cos > 1 - 1e-6:
                change = -float(np.dot(self.R0[best][:, 0], dh))
                e = els[best]
                line = e.line
                parts.append(f"in plan the gap lies along the straight at line {e.line}: making it "
                             f"{e.length + change:.12g} m ({change:+.6g} m) would close it")
            else:
                heading = math.degrees(math.atan2(d[1], d[0]))
                parts.append(f"in plan the end point lies {horiz:.4g} m away at a heading of {heading:.1f} deg; "
                             "no single level straight runs that way")
        return "; ".join(parts) or None, line
