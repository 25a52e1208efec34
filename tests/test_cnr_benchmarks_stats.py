"""The benchmark statistics reproduce the thesis's own appendix figures from its raw samples."""
import pytest

from cnr_benchmarks.core.stats import summarize

# Appendix II, services, Master-Monitor placement, 0 ms: the 20 raw samples and the thesis's summary.
MM_0MS = [19, 24, 19, 22, 35, 31, 19, 23, 27, 20, 30, 22, 19, 18, 21, 20, 22, 20, 18, 20]
# Appendix III, single master, 0 ms start-up of move_base [ms].
SM_STARTUP_0MS = [14520, 12150, 13230, 13630, 13540]


def test_rtt_summary_matches_appendix_ii():
    s = summarize(MM_0MS)
    assert s.average == pytest.approx(22.45)
    assert s.std_dev == pytest.approx(4.73, abs=0.005)
    assert s.std_err == pytest.approx(1.06, abs=0.005)
    assert s.median == pytest.approx(20.5)
    assert s.variance == pytest.approx(22.37, abs=0.005)
    assert s.margin_of_error == pytest.approx(2.07, abs=0.005)
    assert (s.min, s.max, s.range) == (18, 35, 17)


def test_startup_summary_matches_appendix_iii():
    s = summarize(SM_STARTUP_0MS)
    assert s.average == pytest.approx(13414.0)
    assert s.std_dev == pytest.approx(854.01, abs=0.01)
    assert s.std_err == pytest.approx(381.92, abs=0.01)
    assert s.median == pytest.approx(13540.0)


@pytest.mark.parametrize('bad', [[], [1.0, float('nan')]])
def test_rejects_empty_or_nan(bad):
    with pytest.raises(ValueError):
        summarize(bad)
