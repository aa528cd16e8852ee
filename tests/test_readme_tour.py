"""The README's five-minute tour runs as written, twice in a row: its commands are read from the README's code
block, shortened by the substitutions below (each must apply, so a changed README fails here instead of
drifting), and run one by one in a fresh directory that holds only the repository's diagrams/ and examples/.

`sdnn` commands run in this process (click's runner: the numba kernels compile once), other commands (`python`,
`rm`, `mkdir`) as subprocesses; every command must exit 0 and write what it says it writes, into `tour/` only.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner
from html_check import read_page

from flowchart2sdnn.cli import main

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")

#: (pattern, replacement, times it must match): shorter records, fewer starts, files and iterations
SHORTEN = [
    (r"--seconds 30 ", "--seconds 2 ", 1),
    (r"--seconds 50 ", "--seconds 3 ", 1),
    (r"--window 12500 --average 12500", "--window 1000 --average 1000", 1),
    (r"--starts (2|4)", "--starts 2", 2),
    (r"--horizon 100", "--horizon 20", 1),
    (r"(python examples/make_fleet\.py tour/logs)", r"\1 --drives 2 --days 2 --seconds 1", 1),
    (r"^(sdnn (?:identify \S+ tour/bench\S*|diagnose|batch) .*)$", r"\1 --max-iter 15", 5),
    # 15 iterations stop short of convergence, which diagnose refuses to trace from: the shortened tour asks it to
    (r"^(sdnn diagnose .*)$", r"\1 --allow-unconverged", 1),
]

#: what the tour writes (the files its commands name), all in tour/
WRITTEN = ["two_mass.net.json", "two_mass.dot", "two_mass.svg", "bench.csv", "stage1.json", "stage1.chart.yaml",
           "stage2.json", "stage2.html", "diagnose.html", "augmented.yaml",
           "net.csv", "ode.csv", "compare.png", "two_mass.npz", "bode.png", "bench50.csv", "report.json",
           "logs/drive01_day001.csv", "logs/drive02_day002.csv", "fleet.csv", "fleet_report/report.md"]


def tour_commands() -> list[str]:
    block = re.search(r"## A five-minute tour\n\n.*?```bash\n(.*?)```", README, re.S)
    assert block, "the README has no tour block"
    text = block.group(1).replace("\\\n", " ")  # a command continued on the next line
    for pattern, replacement, times in SHORTEN:
        text, n = re.subn(pattern, replacement, text, flags=re.M)
        assert n == times, f"{pattern!r} matched {n} times in the README's tour, expected {times}"
    return [line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]


def test_the_tour_block_has_every_step():
    steps = re.findall(r"^# (\d)\. ", re.search(r"## A five-minute tour\n\n.*?```bash\n(.*?)```", README,
                                                  re.S).group(1), re.M)
    assert steps == [str(k) for k in range(1, 9)]
    assert any("make_fleet.py tour/logs" in c for c in tour_commands())  # step 8 says how to make the logs


def _on_the_bundled_examples(command: str) -> bool:
    """A command that reads only the bundled charts and record (not the bench, the logs or a shortened fit)."""
    return command.startswith("sdnn ") and not re.search(r"bench|logs|fleet|stage2", command)


def _run_tour(root: Path, env: dict) -> dict[str, str]:
    """Run the tour; {command: what an `sdnn` command printed, stdout and stderr}."""
    printed = {}
    for command in tour_commands():
        argv = shlex.split(command, comments=True)
        if argv[0] != "sdnn":
            if argv[0] == "rm":  # `rm -rf tour && mkdir tour`: the shell's
                done = subprocess.run(command, shell=True, cwd=root, capture_output=True, text=True, timeout=60)
            else:
                assert argv[0] == "python", command
                done = subprocess.run([sys.executable, *argv[1:]], cwd=root, env=env, capture_output=True,
                                      text=True, timeout=120)
            assert done.returncode == 0, f"{command}\n{done.stderr}"
            continue
        res = CliRunner().invoke(main, argv[1:])
        assert res.exit_code == 0, f"{command}\n{res.output}"
        printed[command] = res.output
    return printed


def test_the_readme_tour_runs_as_written(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")  # step 5 draws (the plots extra, which the test extra installs)
    for name in ("diagrams", "examples"):
        (tmp_path / name).symlink_to(ROOT / name)
    monkeypatch.chdir(tmp_path)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    before = sorted(p.name for p in tmp_path.iterdir())
    for run in (1, 2):  # the second run meets every file of the first: the tour must start afresh
        printed = _run_tour(tmp_path, env)
        # the README and its tour write the commands in the one argument order: no note saying how to write them
        assert [c for c, out in printed.items() if "argument order" in out or "the chart comes first" in out] == []
        # the charts users copy and the bundled record run clean: no warning (the bench's fits are shortened)
        warned = {c: [line for line in out.splitlines() if re.search(r"^warning|: warning\[", line)]
                  for c, out in printed.items() if _on_the_bundled_examples(c)}
        assert any("examples/data/engine_idle.csv" in c for c in warned)
        assert {c: lines for c, lines in warned.items() if lines} == {}, f"run {run}"
        # the bench's fits stop short, yet the tour's two-mass chart resolves its fastest mode: stage 2, the
        # quasi-online run and the starts in parallel measure no discretization floor or bias worth a warning
        floor = {c: [line for line in out.splitlines() if "warning[FLOOR" in line]
                 for c, out in printed.items() if c.startswith("sdnn identify diagrams/two_mass.yaml")}
        assert len(floor) == 3 and {c: lines for c, lines in floor.items() if lines} == {}, f"run {run}"
        # diagnose's chart resolves the mode of the friction it adds: its final fit's floor is a few % of the
        # residual. Its other warnings are the shortened run's (2 s of data, 15 iterations: the third effect it
        # accepts cannot be told apart, the bias refit stops short); on the 30 s bench it warns of nothing
        [diagnosed] = [out for c, out in printed.items() if c.startswith("sdnn diagnose")]
        percent = re.findall(r"^discretization floor .*: w1 \S+ \(([\d.]+) % of RMS\), w2 \S+ \(([\d.]+) % of RMS\)",
                             diagnosed, re.M)
        assert len(percent) == 1 and max(map(float, percent[0])) < 10, (run, percent)
        assert "warning[FLOOR001]" not in diagnosed and "warning[FLOOR004]" not in diagnosed, f"run {run}"
        tour = tmp_path / "tour"
        missing = [f for f in WRITTEN if not (tour / f).is_file()]
        assert missing == [], f"run {run}"
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted(before + ["tour"]), f"run {run}: outside tour/"
    # the HTML reports: self-contained, every figure there, small enough to attach
    figures, text = read_page(tour / "stage2.html")
    assert figures == ["curve MR1", "curve MR2", "compare", "residual over time", "resid w2 training: bench.csv",
                       "resid w2 validation: bench.csv after the split", "Bode plot"]
    assert "two_mass: identification" in text and "N*m/rad" in text and "95 % interval" in text
    figures, text = read_page(tour / "diagnose.html")
    accepted = re.search(r"accepted: ([^.]*?) stopped", text).group(1)
    assert {"compare", "whiteness", "Bode plot"} <= set(figures), figures
    assert sum(f.startswith("residual_") for f in figures) == accepted.count(" at "), (accepted, figures)
    assert "Candidates, ranked" in text and "Before and after" in text
    for page in ("stage2.html", "diagnose.html"):
        assert (tour / page).stat().st_size < 2_000_000
    # in a notebook the tour's results show themselves briefly: one line, and a summary and HTML under 5 kB
    import flowchart2sdnn as sd

    for value in (sd.read_result(tour / "stage1.json"), sd.read_result(tour / "stage2.json"),
                  sd.read_report(tour / "report.json", tour / "augmented.yaml")):
        assert "\n" not in repr(value) and len(repr(value)) < 300
        assert len(value.summary().encode()) < 5000 and len(value._repr_html_().encode()) < 5000


def test_the_tour_folder_is_ignored_by_git():
    ignored = (ROOT / ".gitignore").read_text(encoding="utf-8").split()
    assert "/tour/" in ignored
    block = re.search(r"## A five-minute tour\n\n.*?```bash\n(.*?)```", README, re.S).group(1)
    written = re.findall(r"(?:-o|--dot|--svg|--html|--report|--control|--bode) (\S+)", block)
    assert written and all(w.startswith("tour/") for w in written), written
