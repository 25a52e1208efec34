"""cnr_testbed.core.flap without a testbed: seeded outage schedules and the traces they become."""
import pytest

from cnr_testbed.core.config import load_trace
from cnr_testbed.core.flap import FlapSettings, Outage, schedule, trace_steps, trace_text


def test_the_same_seed_gives_the_same_schedule_and_another_seed_another():
    assert schedule(7, 30) == schedule(7, 30)
    assert schedule(7, 30) != schedule(8, 30)
    assert schedule(7, 10) == schedule(7, 30)[:10]


def test_events_follow_the_distributions_one_after_the_other():
    events = schedule(3, 400, FlapSettings(lead=2.0))
    assert events[0].start == pytest.approx(2.0)
    for e in events:
        assert 0.2 - 1e-3 <= e.duration <= 15.0 + 1e-3
        assert e.direction in ('both', 'up', 'down') and e.kind in ('outage', 'loss')
        assert e.loss == 1.0 if e.kind == 'outage' else 0.3 - 1e-3 <= e.loss <= 0.9 + 1e-3
    gaps = [b.start - a.end for a, b in zip(events, events[1:])]
    assert all(0.5 - 2e-3 <= g <= 20.0 + 2e-3 for g in gaps)
    # every direction and kind occurs, short and long outages and gaps alike
    assert {e.direction for e in events} == {'both', 'up', 'down'}
    assert {e.kind for e in events} == {'outage', 'loss'}
    assert min(e.duration for e in events) < 0.5 and max(e.duration for e in events) > 10.0
    assert min(gaps) < 1.0 and max(gaps) > 12.0


def test_settings_narrow_the_schedule():
    events = schedule(1, 50, FlapSettings(outage=(2.0, 3.0), gap=(4.0, 4.0), directions=('up',), kinds=('outage',)))
    assert all(2.0 - 1e-3 <= e.duration <= 3.0 + 1e-3 and e.direction == 'up' and e.kind == 'outage' for e in events)
    assert all(b.start - a.end == pytest.approx(4.0, abs=2e-3) for a, b in zip(events, events[1:]))


@pytest.mark.parametrize('settings, field', [
    (FlapSettings(outage=(0.0, 1.0)), 'outage'), (FlapSettings(gap=(5.0, 1.0)), 'gap'),
    (FlapSettings(loss=(0.3, 1.5)), 'loss'), (FlapSettings(directions=('sideways',)), 'directions'),
    (FlapSettings(kinds=()), 'kinds'), (FlapSettings(lead=-1.0), 'lead')])
def test_bad_settings_name_the_field(settings, field):
    with pytest.raises(ValueError, match=field):
        schedule(1, 3, settings)


def test_trace_steps_begin_and_clear_each_event_on_its_direction():
    events = [Outage(1.0, 2.0, 'up', 'outage'), Outage(4.0, 0.5, 'both', 'loss', 0.4)]
    steps = trace_steps(events)
    assert [(s.time, s.direction, s.changes) for s in steps] == [
        (1.0, 'up', {'outage': True}), (3.0, 'up', {'outage': False, 'loss': 0.0}),
        (4.0, 'both', {'loss': 0.4}), (4.5, 'both', {'outage': False, 'loss': 0.0})]
    with pytest.raises(ValueError, match='overlap'):
        trace_steps([Outage(1.0, 2.0, 'up', 'outage'), Outage(2.0, 1.0, 'down', 'outage')])


def test_the_trace_text_is_what_testbed_sh_trace_plays(tmp_path):
    events = schedule(11, 25)
    path = tmp_path / 'flap.tsv'
    path.write_text(trace_text(events))
    loaded = load_trace(str(path))
    expected = trace_steps(events)
    assert [(round(s.time, 3), s.direction) for s in loaded] == [(round(s.time, 3), s.direction) for s in expected]
    assert [s.changes for s in loaded] == [s.changes for s in expected]
