"""The manual's results tables match what their command flies today (reports.manual_tables)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from reports import manual_tables
from reports.compare import DEFAULT_PLANNERS

ROOT = Path(__file__).resolve().parents[1]
PAGES = ROOT / "docs" / "results"


def _fresh_record(name: str) -> dict:
    return {"command": manual_tables.command(name), "planners": list(DEFAULT_PLANNERS),
            "config": manual_tables.table_config(name),
            "checkpoints": manual_tables.current_checkpoints()}


def _page(path: Path, record: dict) -> Path:
    path.write_text(f"# t\n\n| a |\n\n<!-- table record: {json.dumps(record)} -->\n",
                    encoding="utf-8")
    return path


@pytest.mark.parametrize("name", sorted(manual_tables.TABLES))
def test_every_table_of_the_manual_is_fresh(name):
    page = PAGES / f"{name}.md"
    assert page.is_file(), f"{page} is missing: python -m reports.manual_tables {name}"
    reasons = manual_tables.stale_reasons(name, page)
    assert not reasons, (f"docs/results/{name}.md is stale ({'; '.join(reasons)}): "
                         f"python -m reports.manual_tables {name}")


def test_a_changed_default_makes_a_table_stale(tmp_path):
    record = _fresh_record("a4-d25")
    assert manual_tables.stale_reasons("a4-d25", _page(tmp_path / "p.md", record)) == []
    assert "coma" in record["checkpoints"] and "ppo" in record["checkpoints"]
    changed = {**record, "checkpoints": {**record["checkpoints"], "coma": "0" * 64}}
    assert manual_tables.stale_reasons("a4-d25", _page(tmp_path / "p.md", changed)) == [
        f"coma's weights changed (sha256 000000000000 -> {record['checkpoints']['coma'][:12]})"]
    fewer = {**record, "planners": ["ig", "coma"]}
    assert any("not today's defaults" in r
               for r in manual_tables.stale_reasons("a4-d25", _page(tmp_path / "p.md", fewer)))
    other = {**record, "config": {**record["config"], "team": {**record["config"]["team"],
                                                               "n_agents": 8}}}
    assert manual_tables.stale_reasons("a4-d25", _page(tmp_path / "p.md", other)) == [
        "its mission config differs from today's defaults"]


def test_a_page_without_a_record_and_an_unknown_table_are_refused(tmp_path, capsys):
    (tmp_path / "p.md").write_text("# no record\n", encoding="utf-8")
    with pytest.raises(ValueError, match="holds no table record"):
        manual_tables.read_record(tmp_path / "p.md")
    assert manual_tables.main(["nope", "--docs", str(tmp_path / "d")]) == 2
    assert "unknown table(s) ['nope']" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()
