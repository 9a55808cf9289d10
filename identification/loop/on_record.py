"""The closed loop on a measurement folder, as `lss close-loop` runs it: the
base identified by the front door (identification.pipeline.driver, the same
settings as `lss identify`), then the loop (close_loop) on the record's own
problem with the noise and zero tolerance its metadata declares."""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence, Union

from lss_fmu.atomic import write_json_atomic

from ..objective.problem import from_measurement
from ..pipeline.driver import identify_records
from ..pipeline.settings import Settings
from .close_loop import base_from_result, close_loop
from .loop_result import CloseLoopResult
from .settings import LoopSettings

NOISE = ("declared", "estimate")


def close_loop_record(meas, model: str, out: Union[str, Path], *, settings: Optional[Settings] = None,
                      loop_settings: Optional[LoopSettings] = None, base: Union[str, Path, None] = None,
                      rounds: int = 2, effects: Optional[Sequence[str]] = None, window: Optional[float] = None,
                      noise: str = "declared", seed: int = 0, workers: int = 1, progress: bool = False,
                      on_base=None) -> CloseLoopResult:
    """Close the loop on `meas` (a loaded measurement) with contact `model`.

    The base is `base` (an earlier result.json or its folder) or, by default,
    the front door's identification of the record, written to
    OUT/base/result.json (`on_base(result)` is called with it). `noise`:
    "declared" (the sensor's noise from meta.json) or "estimate" (from the
    residual). `window`: only the first seconds of the record."""
    if noise not in NOISE:
        raise ValueError(f"noise {noise!r}: must be one of {', '.join(NOISE)}")
    settings, loop_settings = settings or Settings(), loop_settings or LoopSettings()
    problem = from_measurement(meas, model, free=settings.free, window=window, tare=settings.tare)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if base is None:
        (out / "base").mkdir(exist_ok=True)
        res = identify_records([meas], model, settings, seed=seed, journal=out / "base" / "journal.jsonl",
                               progress=progress, workers=workers)
        write_json_atomic(out / "base" / "result.json", res.to_dict())
        if on_base is not None:
            on_base(res)
        base = out / "base"
    x_base = base_from_result(base, problem)
    sensor = meas.meta.get("sensor") or {}
    res = close_loop(problem, x_base, effects=effects, rounds=rounds, seed=seed, out=out, progress=progress,
                     workers=workers, sensor_offset_std=sensor.get("force_offset_std_N"),
                     noise_std=sensor.get("force_noise_std_N") if noise == "declared" else None,
                     settings=loop_settings)
    write_json_atomic(out / "result.json", {**res.to_dict(), "settings": {"identify": settings.to_dict(),
                                                                          "close_loop": loop_settings.to_dict()}})
    return res


__all__ = ["close_loop_record"]
