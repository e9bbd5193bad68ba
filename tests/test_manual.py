"""The user's manual (README.md and docs/) stays a manual, and names only what exists.

* No dated log lines and no raw CSVs: measurements with dates live in the research record
  (``experiments/``), which the manual points to but never depends on.
* No measured-results tables outside ``docs/results/`` (written by ``python -m
  reports.manual_tables`` from the current defaults): a table row with a ``mean ± SE``
  value, a cell that is a timing, or two final-entropy-like scores (``0.389``) belongs in the
  research record, with a sentence of what it showed in the manual.
* MkDocs cannot link outside ``docs/``: a page points at the README, the record or a source
  file by its repository path in code format, not by a relative link; and every page of
  ``docs/`` is in the site's navigation (``mkdocs.yml``), so the strict build has nothing to
  warn about (CI builds the site with ``mkdocs build --strict`` too).
* Every planner in a ``--planners`` list (or a ``planners=`` argument), every
  ``PLANNER=shipped:NAME``, ``--init shipped:NAME`` and plain ``shipped:NAME``, and every
  ``ipp-train coma|ppo --preset NAME`` the manual names exists in the registries that
  ``ipp-compare`` and ``ipp-train`` resolve them with.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
ISO_DATE = re.compile(r"\b20\d{2}-[01]\d(?:-[0-3]\d)?\b")
LINK = re.compile(r"\]\(([^)\s]+)\)")
FENCED = re.compile(r"```.*?```", re.S)


def manual_pages() -> list[Path]:
    return [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]


def _text(page: Path) -> str:
    return page.read_text(encoding="utf-8")


# --------------------------------------------------------------------------------------------
# Dates, CSVs, links, navigation


def test_the_manual_holds_no_dates():
    dated = [f"{page.relative_to(ROOT)}:{number}: {line.strip()[:100]}"
             for page in manual_pages()
             for number, line in enumerate(_text(page).splitlines(), 1)
             if ISO_DATE.search(line)]
    assert not dated, ("dated lines belong in the research record (experiments/), with a "
                       "short undated summary in the manual:\n" + "\n".join(dated))


def test_the_date_pattern_finds_log_dates_only():
    assert ISO_DATE.search("measured 2026-12-02 on a 2-core VM")
    assert ISO_DATE.search("(2026-11)")
    assert not ISO_DATE.search("--team-sizes 2,4,8 and 1,738,016 agent-transitions, 0.2026")


# Tables of measured results, outside the generated ones
GENERATED = ("results", "reference")  # docs/results/: python -m reports.manual_tables
PLUS_MINUS = re.compile(r"\d\s*±\s*[+-]?\d")
TIMING_CELL = re.compile(r"~?(?:about )?\d[\d.,]*(?:\s*\[[^\]]*\])?\s*(?:ms|s|min)")
SCORE_CELL = re.compile(r"[+-]?\d+\.\d{3}")


def measured_row(line: str) -> bool:
    """Whether a line is a Markdown table row of measured results: a ``mean ± SE`` value, a
    cell holding only a timing (``72 s``, ``7.7 [7.3-10.4] s``), or two cells holding only a
    score with three decimals (final entropy, F1: ``0.389``)."""
    if not line.lstrip().startswith("|"):
        return False
    if PLUS_MINUS.search(line):
        return True
    cells = [cell.strip().strip("*").strip() for cell in line.strip().strip("|").split("|")]
    return (any(TIMING_CELL.fullmatch(cell) for cell in cells)
            or sum(bool(SCORE_CELL.fullmatch(cell)) for cell in cells) >= 2)


def hand_written_pages(root: Path = ROOT) -> list[Path]:
    """The README and the pages of ``docs/`` that no command writes."""
    docs = root / "docs"
    return [root / "README.md", *sorted(page for page in docs.rglob("*.md")
                                        if page.relative_to(docs).parts[0] not in GENERATED)]


def measured_rows(page: Path) -> list[int]:
    """Line numbers of the measured table rows of a page (fenced code left out)."""
    text = FENCED.sub(lambda block: "\n" * block.group().count("\n"), _text(page))
    return [number for number, line in enumerate(text.splitlines(), 1) if measured_row(line)]


def test_the_measured_row_rule_finds_results_not_defaults():
    for row in ("| split | 0.389 | 0.288 | **-0.058 ± 0.010** | **-0.070 ± 0.009** |",
                "| 4 | 25 m | 0.529 | 0.518 | 0.565 | 0.605 |",
                "| local, 2 processes | `--workers 2` | 7.7 [7.7-8.0] s | 9.5 s |",
                "| `ig` | 0.584 ± 0.098 / 0.637 | 0.389±0.068 / 0.797 |"):
        assert measured_row(row), row
    for row in ("| `lookahead_discount` | 0.5 | weight per step further along the path |",
                "| size of a YAML config file | 4 MiB | `IPP_MAX_CONFIG_BYTES` |",
                "| `--address` where nothing answers | an error within 5 s, nothing written |",
                "| 0.0001 | 0.2 | 3 | **E ± S** | **G ± S** | s0 E0 (G0) |",
                "| reward sign | alpha = 22 > 0, beta = -0.5 | `reward.alpha` |",
                "mean 0.461 ± 0.027 in prose, not a table"):
        assert not measured_row(row), row


def test_measured_tables_live_in_the_record_or_the_generated_pages():
    found = [f"{page.relative_to(ROOT)}:{number}" for page in hand_written_pages()
             for number in measured_rows(page)]
    assert not found, ("tables of measured results belong in the research record "
                       "(experiments/<question>/README.md, with the command and date) or in "
                       "docs/results/ (python -m reports.manual_tables); the manual says in a "
                       f"sentence what they showed and names the record page: {found}")


def test_docs_hold_no_csv_files():
    csvs = sorted(str(path.relative_to(ROOT)) for path in DOCS.rglob("*")
                  if path.suffix.lower() == ".csv")
    assert not csvs, f"raw tables belong in experiments/, not docs/: {csvs}"


def test_docs_pages_link_only_inside_docs():
    outside = []
    for page in sorted(DOCS.rglob("*.md")):
        for target in LINK.findall(FENCED.sub("", _text(page))):
            if re.match(r"[a-z]+:", target) or target.startswith("#"):
                continue
            linked = (page.parent / target.partition("#")[0]).resolve()
            if not linked.is_relative_to(DOCS):
                outside.append(f"{page.relative_to(ROOT)}: {target}")
    assert not outside, ("the site cannot link outside docs/; name the file as a code-formatted "
                         f"repository path instead: {outside}")


def nav_pages() -> list[str]:
    """The pages of ``mkdocs.yml``'s nav (every ``...: page.md`` after ``nav:``)."""
    config = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    nav = config.split("\nnav:\n", 1)[1]
    return re.findall(r":\s+(\S+\.md)\s*$", nav, flags=re.M)


def test_every_page_of_docs_is_in_the_site_navigation():
    listed = nav_pages()
    assert "index.md" in listed and len(listed) == len(set(listed))
    pages = {str(page.relative_to(DOCS)) for page in DOCS.rglob("*.md")}
    assert pages == set(listed), (f"pages not in mkdocs.yml's nav: {sorted(pages - set(listed))}; "
                                  f"nav entries without a page: {sorted(set(listed) - pages)}")


# --------------------------------------------------------------------------------------------
# Planners, shipped policies and presets the manual names

PLANNERS_FLAG = re.compile(r"--planners[ =]+[\"']?([\w:=./+,-]+)")
PLANNERS_ARG = re.compile(r"planners=(?:\[([^\]]*)\]|[\"']([^\"']+)[\"'])")
SHIPPED = re.compile(r"(?:\b([a-z0-9_]+)=|--init\s+)?shipped:([a-z0-9][a-z0-9-]*)\b")
PRESET = re.compile(r"ipp-train (coma|ppo)\b[^\n`]*?--preset[ =]([a-z0-9][a-z0-9-]*)")


def _registries() -> dict[str, object]:
    from baselines.sb3.ppo import SHIPPED_POLICIES as PPO_SHIPPED
    from baselines.sb3.ppo_training import PPO_PRESETS
    from coma.config import PRESETS
    from coma.persistence import SHIPPED_POLICIES as COMA_SHIPPED
    from coma.recipes import RECIPES
    from ipp_toolkit.planning import available_planners

    return {"planners": set(available_planners()),
            "shipped": {"coma": set(COMA_SHIPPED), "ppo": set(PPO_SHIPPED),
                        "sb3": set(PPO_SHIPPED)},
            "presets": {"coma": set(PRESETS) | set(RECIPES), "ppo": set(PPO_PRESETS)}}


def _joined(text: str) -> str:
    """Commands continued over lines with a backslash, joined into one line each."""
    return re.sub(r"\\\n\s*", " ", text)


def _own_planners(text: str) -> set[str]:
    """Planners a page defines itself (``register_planner("NAME")``, or an entry point in its
    ``ipp_toolkit.planners`` group): the examples of how to add one."""
    names = set(re.findall(r"register_planner\(\s*[\"']([^\"']+)[\"']", text))
    group = r"\[project\.entry-points\.\"ipp_toolkit\.planners\"\]\n(.*?)(?:\n\[|```)"
    for block in re.findall(group, text, flags=re.S):
        names |= set(re.findall(r"^\s*\"?([\w-]+)\"?\s*=", block, flags=re.M))
    return names


def named_planners(text: str) -> list[str]:
    """Every ``[LABEL:]NAME[=CHECKPOINT]`` of a ``--planners`` list or a ``planners=`` argument
    (placeholders in capitals and ``all`` left out)."""
    text = _joined(text)
    lists = PLANNERS_FLAG.findall(text)
    for listed, joined in PLANNERS_ARG.findall(text):
        lists.append(joined or ",".join(re.findall(r"[\"']([^\"']+)[\"']", listed)))
    specs = []
    for items in lists:
        for item in items.split(","):
            head = item.partition("=")[0]
            name = head.rpartition(":")[2]
            if name and name != "all" and name == name.lower() and re.fullmatch(r"[\w-]+", name):
                specs.append(item)
    return specs


def problems(text: str, registries: dict[str, object]) -> list[str]:
    """What a page of the manual names that the registries do not hold."""
    planners = registries["planners"] | _own_planners(text)
    shipped, presets = registries["shipped"], registries["presets"]
    found = []
    for item in named_planners(text):
        head, _, checkpoint = item.partition("=")
        name = head.rpartition(":")[2]
        if name not in planners:
            found.append(f"unknown planner {name!r} in {item!r}")
        elif checkpoint.startswith("shipped:") and name not in shipped:
            found.append(f"planner {name!r} has no shipped policies ({item!r})")
    for planner, name in SHIPPED.findall(_joined(text)):
        if planner in shipped:
            known = shipped[planner]
        elif planner:
            found.append(f"planner {planner!r} has no shipped policies ({planner}=shipped:{name})")
            continue
        else:  # --init shipped:NAME (COMA) or a policy named in prose: any shipped policy
            known = set().union(*shipped.values())
        if name not in known:
            found.append(f"unknown shipped policy {name!r}"
                         + (f" of {planner!r}" if planner else ""))
    for trainer, name in PRESET.findall(_joined(text)):
        if name not in presets[trainer]:
            found.append(f"unknown preset {name!r} of ipp-train {trainer}")
    return found


def test_the_checks_find_what_does_not_exist():
    registries = {"planners": {"ig", "coma", "ppo"}, "shipped": {"coma": {"scratch"},
                                                                   "ppo": {"split"}},
                  "presets": {"coma": {"cpu", "scratch"}, "ppo": {"split"}}}
    text = ("```bash\nipp-compare --trials 2 \\\n  --planners ig,mine:coma=runs/x/best.pt,nope\n"
            "ipp-compare --planners coma=shipped:gone,ppo=shipped:split,ig=shipped:x\n"
            "ipp-train coma --out x --preset old\nipp-train coma --init shipped:scratch\n```\n"
            "compare(planners=[\"ig\", \"ghost\"]) and `ppo=shipped:NAME`, `--planners all`\n")
    assert problems(text, registries) == [
        "unknown planner 'nope' in 'nope'",
        "planner 'ig' has no shipped policies ('ig=shipped:x')",
        "unknown planner 'ghost' in 'ghost'",
        "unknown shipped policy 'gone' of 'coma'",
        "planner 'ig' has no shipped policies (ig=shipped:x)",
        "unknown preset 'old' of ipp-train coma"]
    assert problems('@register_planner("mine")\n`--planners ig,mine`', registries) == []


def test_the_manual_names_only_planners_and_policies_that_exist():
    registries = _registries()
    assert {"ig", "ig_learned", "coma", "ppo", "sb3"} <= registries["planners"]
    found = [f"{page.relative_to(ROOT)}: {problem}" for page in manual_pages()
             for problem in problems(_text(page), registries)]
    assert not found, "\n".join(found)
