"""The CUSUM bias test: silent on zero-mean noise of the modelled spread, an alarm within the stated
delay for a bias of k standard deviations, on the right row and with the right sign."""

from __future__ import annotations

import numpy as np
import pytest

from switchobs_core.runtime.bias import BiasDetector, cusum_delay


def _delay(b: float, seed: int) -> int:
    rng = np.random.default_rng(seed)
    d = BiasDetector((4, 4))
    for k in range(1, 1000):
        s = rng.standard_normal(4)
        s[2] += b
        if d.update(1, None, s) is not None:
            return k
    return 1000


def test_no_alarm_on_noise_of_the_modelled_spread():
    rng = np.random.default_rng(0)
    d = BiasDetector((4, 4))
    alarms = sum(d.update(1 + k % 2, None, rng.standard_normal(4)) is not None for k in range(20_000))
    assert alarms == 0          # about 2e-8 per row, direction and sample: 3e-3 expected in 160k draws
    assert d.alarms == 0


@pytest.mark.parametrize("b", [3.0, 4.0, 5.0])
def test_a_bias_of_b_sigma_alarms_within_the_stated_delay(b):
    delays = [_delay(b, seed) for seed in range(200)]
    # Siegmund's approximation of the mean delay, within 35 % (it is an approximation of a mean)
    assert abs(np.mean(delays) - cusum_delay(b)) <= 0.35 * cusum_delay(b)
    assert max(delays) <= 3 * cusum_delay(b)


def test_the_alarm_names_the_row_and_the_sign_and_restarts():
    d = BiasDetector((2, 4))
    assert d.update(2, [1, 3], np.array([0.0, -6.0])) is None      # g = 5 <= 8
    alarm = d.update(2, [1, 3], np.array([0.0, -6.0]))              # g = 10 > 8
    assert alarm is not None and (alarm.channel, alarm.row, alarm.sign) == (2, 3, -1) and alarm.g == 10.0
    assert "reads low" in alarm.describe("agent2.p_y") and "agent2.p_y" in alarm.describe("agent2.p_y")
    assert np.all(d.g_neg[1] == 0.0)        # the statistics restart after an alarm
    assert d.update(1, None, np.array([np.nan, 0.0])) is None     # a non-finite input changes nothing
    assert cusum_delay(0.5) == np.inf
