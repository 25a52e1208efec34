"""cnr_benchmarks.results without ROS: an experiment's page header (measured, commit, machine, command), a
re-run replacing the page, and the TSV and JSON writers."""
from __future__ import annotations

import datetime
import json
import os
import re
import shutil
import subprocess

import pytest

from cnr_benchmarks import results

HEADER = re.compile(r'# (?P<title>.+) \((?P<ref>.+)\)\n\n\| measured \| commit \| machine \| command \|\n'
                    r'\|---\|---\|---\|---\|\n\| (?P<date>\d{4}-\d\d-\d\d) \| (?P<commit>[^|]+) \| '
                    r'(?P<machine>[^|]+) \| `(?P<command>[^`]+)` \|\n\n')


def _git(ws, *args):
    subprocess.run(['git', '-C', str(ws), *args], check=True, capture_output=True,
                   env=dict(os.environ, GIT_AUTHOR_NAME='t', GIT_AUTHOR_EMAIL='t@t', GIT_COMMITTER_NAME='t',
                            GIT_COMMITTER_EMAIL='t@t'))


def test_page_header_outside_git_and_rerun_replaces_it(tmp_path):
    out = tmp_path / 'docs' / 'results' / 'rtt'
    text = results.write_page(str(out), 'RTT between client and monitor', 'thesis Table 4-1', 'first body\n',
                              'launch_scripts/bench_rtt.sh --samples 5', ws=str(tmp_path))
    page = (out / 'README.md').read_text()
    assert page == text
    m = HEADER.match(page)
    assert m, page
    assert m['title'] == 'RTT between client and monitor' and m['ref'] == 'thesis Table 4-1'
    assert m['date'] == datetime.date.today().isoformat()
    assert m['commit'] == 'unknown'
    assert f'{os.cpu_count()} cores' in m['machine']
    assert m['command'] == 'launch_scripts/bench_rtt.sh --samples 5'
    assert page.endswith('first body\n')

    results.write_page(str(out), 'RTT between client and monitor', 'thesis Table 4-1', 'second body',
                       'launch_scripts/bench_rtt.sh', ws=str(tmp_path))
    page = (out / 'README.md').read_text()
    assert 'first body' not in page and page.endswith('second body\n')
    assert HEADER.match(page)['command'] == 'launch_scripts/bench_rtt.sh'
    assert sorted(os.listdir(out)) == ['README.md']          # no temporary files left behind


@pytest.mark.skipif(shutil.which('git') is None, reason='needs git')
def test_commit_is_the_short_head_and_dirty_with_changes(tmp_path):
    _git(tmp_path, 'init', '-q')
    (tmp_path / 'a.txt').write_text('a\n')
    _git(tmp_path, 'add', 'a.txt')
    _git(tmp_path, 'commit', '-q', '-m', 'a')
    head = subprocess.run(['git', '-C', str(tmp_path), 'rev-parse', '--short', 'HEAD'], capture_output=True,
                          text=True, check=True).stdout.strip()
    assert results.git_commit(str(tmp_path)) == head
    (tmp_path / 'a.txt').write_text('b\n')
    assert results.git_commit(str(tmp_path)) == head + '+dirty'
    page = results.write_page(str(tmp_path / 'out'), 'T', 'R', 'body', 'x.sh', ws=str(tmp_path))
    assert HEADER.match(page)['commit'] == head + '+dirty'


def test_command_line_quotes_arguments():
    assert results.command_line('launch_scripts/exp_deadzone.sh', ['--modes', 'normal,network_aware', 'a b']) == \
        "launch_scripts/exp_deadzone.sh --modes normal,network_aware 'a b'"


def test_machine_names_the_cpu_model(tmp_path):
    info = tmp_path / 'cpuinfo'
    info.write_text('processor\t: 0\nmodel name\t: Test CPU 9000\n')
    assert results.machine(str(info)).startswith(f'Test CPU 9000, {os.cpu_count()} cores, ')


def test_tsv_and_json(tmp_path, capsys):
    path = results.write_tsv(str(tmp_path / 'x.tsv'), ['a', 'b'], [[1, 0.5], ['x', None]])
    assert open(path).read() == 'a\tb\n1\t0.500\nx\t\n'
    results.save_json(str(tmp_path / 'sub' / 'x.json'), [{'name': 'n', 'value': 1.5}])
    assert json.load(open(tmp_path / 'sub' / 'x.json')) == [{'name': 'n', 'value': 1.5}]
    assert capsys.readouterr().out == f'wrote {tmp_path / "sub" / "x.json"}\n'


def test_folders():
    assert results.results_dir('campaign_slowdown4.5', '/ws') == '/ws/docs/results/campaign_slowdown4.5'
    assert results.scratch_dir('deadzone', '/ws') == '/ws/bench_results/deadzone'


def test_page_with_figure_and_tables(tmp_path):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    out = tmp_path / 'startup'
    results.write_page(str(out), 'T', 'R', '![x](x.png)', 'x.sh', {'x.png': fig},
                       {'rows.tsv': (['a', 'b'], [{'a': 1, 'b': 2.0}, [3, None]])}, ws=str(tmp_path))
    assert (out / 'x.png').read_bytes().startswith(b'\x89PNG')
    assert (out / 'rows.tsv').read_text() == 'a\tb\n1\t2.000\n3\t\n'
    assert sorted(os.listdir(out)) == ['README.md', 'rows.tsv', 'x.png']
