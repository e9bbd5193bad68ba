"""Several paired columns in one summary: what a planner adds over IG and over ig_spatial.

The tables' numbers are checked on hand-sized rows; the command lines on tiny runs.
"""

from __future__ import annotations

import csv
import io
import math

import pytest

from reports.tables import (
    Paired,
    Stat,
    Summary,
    flown_references,
    reference_labels,
    summarise,
    to_csv,
    to_latex,
    to_markdown,
)

# Final entropy (step 3) per planner and mission, chosen so the differences are round:
#   mine - ig         = -0.1, -0.2, -0.3: mean -0.2, sd 0.1, SE 0.1/sqrt(3), ahead in 3 of 3;
#   mine - ig_spatial = +0.1, -0.1, +0.3: mean +0.1, sd 0.2, SE 0.2/sqrt(3), ahead in 1 of 3;
#   ig_spatial - ig   = -0.2, -0.1, -0.6: mean -0.3, sd sqrt(0.07), ahead in 3 of 3.
FINAL = {"ig": (0.7, 0.7, 0.7), "ig_spatial": (0.5, 0.6, 0.1), "mine": (0.6, 0.5, 0.4)}


def hand_rows() -> list[dict]:
    rows = []
    for planner, finals in FINAL.items():
        for mission, final in enumerate(finals):
            rows.append({"planner": planner, "mission": mission, "step": 0, "entropy": 1.0})
            rows.append({"planner": planner, "mission": mission, "step": 3, "entropy": final})
    return rows


def table_cells(text: str) -> dict[str, list[str]]:
    return {cells[0]: cells[1:] for cells in
            ([c.strip() for c in line.strip("|").split(" | ")] for line in text.splitlines()
             if line.startswith("| "))}


def test_two_references_give_two_paired_columns_with_hand_computed_values():
    summary = summarise(hand_rows(), metrics=("entropy",))  # the default: ig, ig_spatial
    assert summary.references == ("ig", "ig_spatial")
    vs_ig, vs_spatial = summary.paired_to["ig"]["mine"], summary.paired_to["ig_spatial"]["mine"]
    assert vs_ig.mean == pytest.approx(-0.2) and vs_ig.se == pytest.approx(0.1 / math.sqrt(3))
    assert vs_ig.win_rate == 1.0 and vs_ig.n == 3
    assert vs_spatial.mean == pytest.approx(0.1)
    assert vs_spatial.se == pytest.approx(0.2 / math.sqrt(3))
    assert vs_spatial.win_rate == pytest.approx(1 / 3)
    spatial = summary.paired_to["ig"]["ig_spatial"]
    assert spatial.mean == pytest.approx(-0.3)
    assert spatial.se == pytest.approx(math.sqrt(0.07) / math.sqrt(3))
    # The first reference stays where code that knows one reference reads it.
    assert summary.reference == "ig" and summary.paired is summary.paired_to["ig"]
    assert "ig" not in summary.paired_to["ig"]  # a reference has no cell in its own column

    cells = table_cells(to_markdown(summary))
    assert cells["Planner"][-3:] == ["Δ vs ig", "Δ vs ig_spatial", "ms/step"]
    assert cells["mine"][-3:-1] == ["-0.200 ± 0.058 (100 %)", "+0.100 ± 0.115 (33 %)"]
    assert cells["ig"][-3:-1] == ["-", "+0.300 ± 0.153 (0 %)"]
    assert cells["ig_spatial"][-3:-1] == ["-0.300 ± 0.153 (100 %)", "-"]
    assert "Δ vs ig, Δ vs ig_spatial: final entropy minus" in to_markdown(summary)


def test_the_csv_keeps_the_first_references_columns_and_adds_the_next_after_them():
    summary = summarise(hand_rows(), metrics=("entropy",), checkpoints={"mine": "w sha256:0"})
    text = to_csv(summary)
    header = text.splitlines()[0].split(",")
    paired = header[header.index("plan_ms_per_step") + 1:]
    assert paired == ["entropy_final_minus_ig_mean", "entropy_final_minus_ig_se",
                      "win_rate_vs_ig", "entropy_final_minus_ig_spatial_mean",
                      "entropy_final_minus_ig_spatial_se", "win_rate_vs_ig_spatial",
                      "checkpoint"]
    rows = {row["planner"]: row for row in csv.DictReader(io.StringIO(text))}
    assert float(rows["mine"]["entropy_final_minus_ig_spatial_mean"]) == pytest.approx(0.1)
    assert float(rows["mine"]["win_rate_vs_ig"]) == 1.0
    assert rows["ig"]["entropy_final_minus_ig_mean"] == ""  # its own column stays empty
    assert rows["ig_spatial"]["entropy_final_minus_ig_spatial_se"] == ""
    assert float(rows["ig"]["entropy_final_minus_ig_spatial_mean"]) == pytest.approx(0.3)


def test_the_latex_table_has_a_column_per_reference():
    text = to_latex(summarise(hand_rows(), metrics=("entropy",)))
    assert r"\begin{tabular}{l ccc r r r}" in text
    assert r"$\Delta$ vs ig & $\Delta$ vs ig\_spatial & ms/step \\" in text
    mine = next(line for line in text.splitlines() if line.startswith("mine &"))
    assert mine.endswith(r"& -0.200 $\pm$ 0.058 (100 \%) & +0.100 $\pm$ 0.115 (33 \%) & - \\")


def test_the_reference_argument_takes_a_label_a_list_or_a_sequence():
    rows = hand_rows()
    assert summarise(rows, reference="ig").references == ("ig",)
    assert summarise(rows, reference="ig_spatial,ig").references == ("ig_spatial", "ig")
    assert summarise(rows, reference=["ig_spatial"]).reference == "ig_spatial"
    assert summarise(rows, reference="ig,absent").references == ("ig",)  # not in the rows
    none = summarise([r for r in rows if r["planner"] == "mine"])
    assert none.references == () and none.reference == "" and "Δ" not in to_markdown(none)
    assert reference_labels(" ig , ig_spatial,,ig ") == ("ig", "ig_spatial")


def test_flown_references_skip_unflown_defaults_and_refuse_named_ones():
    assert flown_references(None, ["ig", "random"]) == ("ig",)
    assert flown_references(None, ["coma", "random"]) == ()
    assert flown_references("ig_spatial,ig", ["ig", "ig_spatial"]) == ("ig_spatial", "ig")
    with pytest.raises(ValueError, match="reference planner 'ig_spatial' is not among"):
        flown_references("ig,ig_spatial", ["ig", "random"])
    with pytest.raises(ValueError, match="names no planner"):
        flown_references(" , ", ["ig"])


def test_a_summary_built_with_one_reference_still_renders_its_column():
    paired = {"mine": Paired(-0.2, 0.05, 1.0, 3)}
    summary = Summary(planners=("ig", "mine"), metrics=("entropy",), steps=(3,), budget=3,
                      stats={("mine", "entropy", 3): Stat(0.5, 0.1, 3)}, plan_ms={},
                      missions=3, reference="ig", paired=paired)
    assert summary.paired_to == {"ig": paired}
    assert table_cells(to_markdown(summary))["mine"][-2] == "-0.200 ± 0.050 (100 %)"


def test_only_a_planner_ahead_by_two_standard_errors_is_bold_not_an_identical_one():
    from reports.generalisation import _paired_text

    assert _paired_text(Paired(-0.02, 0.01, 0.7, 50)).startswith("**")
    assert not _paired_text(Paired(-0.019, 0.01, 0.7, 50)).startswith("**")
    # The same missions flown identically: mean and SE 0, level rather than ahead.
    assert _paired_text(Paired(0.0, 0.0, 0.0, 50)) == "+0.000 ± 0.000 (0 %)"
    assert not _paired_text(Paired(0.02, 0.005, 0.1, 50)).startswith("**")
