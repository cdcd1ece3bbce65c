"""The weld-line filter's start (cslx.runtime.filter_start), on synthetic bead sequences: a
first bead that is far off, or implausibly wide, does not capture the filter."""

import dataclasses
import math

from cslx.runtime.line_filter import KalmanConfig, WeldLineFilter

X_REF = 150.0


def _run(config: KalmanConfig, beads) -> list[float]:
    """Feed (y mm, confidence, width mm) beads, one per 1.5 mm of straight travel, to a
    cold filter; the filtered offset after each (NaN while it has none)."""
    kf = WeldLineFilter(config, X_REF)
    out = []
    for i, (y, conf, width) in enumerate(beads):
        if i:
            kf.predict(1.5, 0.0, odometry=True)
        kf.update(X_REF, y, conf, width)
        out.append(float(kf.x[0]) if kf.initialised else math.nan)
    return out


def test_a_far_off_first_bead_is_dropped_once_the_next_two_agree():
    """First bead 10 mm off the weld (y = 0), then beads on it: without the rule the gate
    rejects the true beads until three rejected ones agree (the filter off for 3 frames);
    with `start_agree` 3 it restarts on the second and third."""
    beads = [(10.0, 0.4, 30.0)] + [(0.0, 0.3, 18.0)] * 4
    off = _run(dataclasses.replace(KalmanConfig(), start_agree=0), beads)
    on = _run(dataclasses.replace(KalmanConfig(), start_agree=3), beads)
    assert abs(off[2]) > 9.0  # still captured by the first bead
    assert abs(on[2]) < 1e-9 and abs(on[3]) < 0.05


def test_a_near_first_bead_is_dropped_and_agreeing_starts_are_kept():
    """First bead 3 mm off (inside the gate, blended in); the rule removes what is left of
    it on the third bead. A start whose beads agree is left alone."""
    beads = [(3.0, 0.37, 31.0), (0.0, 0.24, 19.0), (0.0, 0.32, 18.8), (0.0, 0.3, 18.7)]
    off = _run(dataclasses.replace(KalmanConfig(), start_agree=0), beads)
    on = _run(dataclasses.replace(KalmanConfig(), start_agree=3), beads)
    assert off[2] > 0.1 and abs(on[2]) < 1e-9
    agree = [(0.3, 0.4, 18.0), (-0.2, 0.3, 18.0), (0.1, 0.3, 18.0), (0.0, 0.3, 18.0)]
    config = dataclasses.replace(KalmanConfig(), start_agree=0)
    assert _run(dataclasses.replace(config, start_agree=3), agree) == _run(config, agree)


def test_an_implausible_width_waits_but_a_real_wide_bead_still_starts():
    """`start_width_mm` (10, 24): a 31 mm first bead does not start the filter, the next
    19 mm one does; a weld really 30 mm wide starts on its second bead (two that agree)."""
    config = dataclasses.replace(KalmanConfig(), start_width_mm=(10.0, 24.0))
    out = _run(config, [(3.0, 0.37, 31.0), (0.0, 0.24, 19.0), (0.1, 0.3, 18.8)])
    assert math.isnan(out[0]) and abs(out[1]) < 1e-9
    wide = _run(config, [(0.2, 0.4, 30.0), (0.0, 0.4, 29.0), (0.1, 0.4, 30.5)])
    assert math.isnan(wide[0]) and math.isfinite(wide[1])
    two_apart = _run(config, [(5.0, 0.4, 30.0), (0.0, 0.4, 29.0), (0.0, 0.4, 30.0)])
    assert math.isnan(two_apart[1]) and abs(two_apart[2]) < 1e-9
