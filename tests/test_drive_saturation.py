"""The PI drive riding its thrust limit (fmu_src/drive.c).

A start at full thrust with a low K_P, where K_I e outpaces K_P de/dt, holds
the command on the saturation (a sliding motion). With the integrator
switched off at the limit at once, zdot switched at every step and the
solver fell to steps of 1e-7 s: 170 CPU-s for 0.3 s of layout 1 where 0.3
s suffice, a few such points in a complex costing more than all the others
(on the rig's start-up of one layout-1 record, 13 of 147 points). The
switch spread over a band of 1e-3 F_max keeps zdot continuous; the command
stays within the band of the limit, as the sliding motion has it.
"""
from __future__ import annotations

import numpy as np

from lss_fmu.runner import ChainSimulator

F_MAX = 400.0


def _start(kp: float, ki: float, seconds: float = 0.3) -> np.ndarray:
    params = {"layout.name": "layout1", "chain.v_init": 0.0, "chain.transducer": 0, "drive.v_ref": 0.0,
              "chain.relax_time": 1.034, "chain.s_start": 17.75, "chain.pretension": 0.0231,
              "drive.Kp": kp, "drive.Ki": ki, "drive.F_max": F_MAX}
    rows = []
    with ChainSimulator() as sim:
        for t, val in sim.stream(0.5 / 600, ["solver.h_last", "drive.F_cmd"], params, 1e-6,
                                 inputs={"drive.v_ref": lambda t: 1.5}):
            rows.append([t, *val])
            if t >= seconds:
                break
    return np.asarray(rows)


def test_a_drive_on_its_limit_keeps_the_solver_step(fmu_file):
    out = _start(269.0, 394.0)
    t, h, F = out[:, 0], out[:, 1], out[:, 2]
    riding = (t > 0.02) & (t < 0.3)
    # the command on its limit, within the band, throughout
    assert np.all(F[riding] <= F_MAX + 1e-9) and np.all(F[riding] >= F_MAX * (1 - 2e-3)), F[riding].min()
    # and the solver's steps where they are off the limit (1e-4 s), not 1e-7
    assert np.min(h[riding]) > 1e-5, np.min(h[riding])


def test_a_drive_off_its_limit_is_as_before(fmu_file):
    """K_P 445 leaves the limit at once: the band never reached, the steps as ever."""
    out = _start(445.0, 394.0)
    assert np.min(out[(out[:, 0] > 0.02), 1]) > 1e-5
