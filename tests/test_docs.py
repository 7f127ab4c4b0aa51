"""The guide a newcomer reads: README.md and docs/ hold together, say nothing of how the project
is worked on, and quote only figures their results files hold."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path
from urllib.parse import unquote

import pytest

from mission.campaigns.figures import CLI_PAGE, RESULTS_DIR, load_figures, pages, quoted
from mission.cli.reference import cli_reference

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
# the words split so that a grep for them does not find this file
PROCESS_WORDS = re.compile(
    "|".join([r"stop [0-9]+", r"issue [0-9]+", "fast" + " hour", "this" + " session"]), re.I
)


def _guide() -> list[Path]:
    return [*pages(REPO), REPO / "CHANGELOG.md", REPO / "logs" / "README.md",
            *sorted((REPO / "docs").glob("*/*.md"))]  # fmt: skip


def _anchors(path: Path) -> set[str]:
    """GitHub's anchors for a page's headings."""
    anchors = set()
    for heading in re.findall(r"^#+ (.+)$", path.read_text(), flags=re.M):
        text = re.sub(r"[`*_]", "", heading.strip().lower())
        anchors.add(re.sub(r"\s", "-", re.sub(r"[^\w\s-]", "", text)))
    return anchors


def test_every_relative_link_in_the_guide_resolves() -> None:
    broken = []
    for page in _guide():
        for target in LINK.findall(page.read_text()):
            if re.match(r"[a-z]+:", target):
                continue
            file, _, anchor = unquote(target).partition("#")
            path = (page.parent / file).resolve() if file else page
            if not path.exists() or REPO not in path.parents:
                broken.append(f"{page.relative_to(REPO)}: {target}")
            elif anchor and path.suffix == ".md" and anchor not in _anchors(path):
                broken.append(f"{page.relative_to(REPO)}: {target} (no such heading)")
    assert not broken, "\n".join(broken)


def test_the_project_speaks_of_what_it_does_not_how_it_was_worked_on() -> None:
    tracked = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard",
         "*.md", "*.py", "*.yaml", "*.toml", "Makefile"],
        cwd=REPO, capture_output=True, text=True, check=True,
    ).stdout.split()  # fmt: skip
    found = [
        f"{name}:{n}: {line.strip()}"
        for name in tracked
        if (REPO / name).exists()
        for n, line in enumerate((REPO / name).read_text().splitlines(), 1)
        if PROCESS_WORDS.search(line)
    ]
    assert not found, "\n".join(found)


def test_every_quoted_figure_is_its_results_file_s() -> None:
    figures = load_figures(RESULTS_DIR)
    assert figures, "docs/results/ holds no results: run `groundfx figures`"
    wrong = []
    count = 0
    for page in pages(REPO):
        for name, written in quoted(page.read_text()):
            count += 1
            if figures.get(name) != written:
                wrong.append(f"{page.name}: {name} is {written!r}, results {figures.get(name)!r}")
    assert count >= 10  # the headline results are quoted from results files
    assert not wrong, "\n".join(wrong) + "\n(`groundfx figures --rewrite-only` refreshes them)"


@pytest.mark.parametrize("source", sorted(p.stem for p in RESULTS_DIR.glob("*.json")))
def test_a_results_file_says_how_it_was_made(source: str) -> None:
    import json

    record = json.loads((RESULTS_DIR / f"{source}.json").read_text())
    assert record["command"].startswith("groundfx ")
    assert {"date", "commit", "machine", "load_average_1min", "figures"} <= set(record)


def test_the_command_reference_is_the_parsers_help() -> None:
    assert CLI_PAGE.read_text() == cli_reference(), "`groundfx figures --rewrite-only` refreshes it"


def test_a_newcomer_finds_the_essentials_early_in_a_short_readme() -> None:
    lines = README.read_text().splitlines()
    assert len(lines) <= 300
    head = "\n".join(lines[:150])
    assert "groundfx demo" in head
    assert re.search(r"```yaml\n(.*\n)*?waypoints:", head), "a mission YAML to copy"
    assert "groundfx review" in head
    assert "groundfx gap diagnose" in head


def test_the_demo_ends_with_its_models_side_by_side_and_how_to_review_them() -> None:
    from mission.campaigns.demo import demo_table

    summaries = {
        model: {"landing_error_m": 0.0012, "hold_z_rms_error_m": 0.0004,
                "touchdown_speed_m_s": 0.08, "recording": f"logs/x-{model}.rrd"}
        for model in ("analytic", "neural", "none")
    }  # fmt: skip
    table = demo_table(summaries).splitlines()
    assert table[0].startswith("| model | landing error (mm) | hold RMS (mm) | touchdown speed")
    assert "| neural | 1.20 | 0.40 | 0.080 | logs/x-neural.rrd |" in table
    assert "  groundfx review logs/x-none.rrd" in table


def test_every_mission_the_guide_shows_is_one_the_vehicle_accepts(tmp_path: Path) -> None:
    from mission.cli.main import main

    blocks = [
        block
        for page in pages(REPO)
        for block in re.findall(r"```yaml\n(.*?)```", page.read_text(), flags=re.S)
        if "waypoints:" in block
    ]
    assert len(blocks) >= 2
    for n, block in enumerate(blocks):
        path = tmp_path / f"mission{n}.yaml"
        path.write_text(block)
        assert main(["mission", "check", str(path)]) == 0, block
