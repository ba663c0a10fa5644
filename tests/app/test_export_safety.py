"""Exports that are safe in any spreadsheet: no piece of a cell that a spreadsheet could read as a formula, after
splitting the cell on a comma, semicolon, tab or line break and trimming whitespace (fullwidth signs included);
no NUL; and the documented reverse (`app.analysis.export_csv.restore`, the codebook's rule) gives back exactly what was
typed. End to end through the real app and `foil export`, on SQLite and PostgreSQL."""

from __future__ import annotations

import csv
import json
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.analysis.export_csv import export_study, neutralise, restore
from tests.support.survey import answer_for, start

# What Excel, LibreOffice or Google Sheets may take for the start of a formula, fullwidth and small forms included.
SIGNS = "=+-@\uff1d\uff0b\uff0d\uff20\ufe66\ufe62\ufe63\ufe6b\u2212"
PIECES = re.compile(r"[,;\t\n\r]")
ATTACKS = [
    "x;=cmd|' /C calc'!A0;",
    "x;=1+1;",
    "a,=1+1",
    "a\t=1+1",
    "a\n=1+1",
    "a\r\n@SUM(A1)",
    "\n=1+1",
    " =1+1",
    "\u3000=1+1",
    "\xa0+1",
    "\uff1d1+1",
    "x;\uff0bcmd",
    "x, \uff20SUM(A1)",
    "\u22121",
    "nul\x00byte",
    "\x00",
    "'",
    "''",
    "x;'=1",
    "x; '=1",
    "\u2400",
    "\u2400\x00\u24000",
    "=1;=2,=3\t=4\n=5",
    "NA",
    "null",
    "\t",
    ";",
    "plain words, with a comma; and a semicolon",
]


def assert_safe(cell: str) -> None:
    assert "\x00" not in cell, cell
    for piece in PIECES.split(cell):
        assert not piece.strip()[:1] or piece.strip()[0] not in SIGNS, (cell, piece)
    assert not cell.startswith(("\t", "\r", "\n")), cell


@pytest.mark.parametrize("typed", ATTACKS)
def test_every_piece_of_a_cell_is_neutralised_and_the_text_comes_back(typed):
    cell = neutralise(typed)
    assert_safe(cell)
    assert restore(cell) == typed


@settings(max_examples=400, deadline=None)
@given(st.text(st.sampled_from(SIGNS + ",;\t\n\r '\x00\u2400\u3000aN"), max_size=12) | st.text(max_size=40))
def test_neutralise_is_safe_and_reverses_for_any_text(typed):
    cell = neutralise(typed)
    assert_safe(cell)
    assert restore(cell) == typed


def test_typed_attacks_are_exported_safe_and_exactly(make_client, tmp_path):
    client = make_client({"platform": '"none"', "assignment": '"balanced"'})
    page = client.post("/study", data=answer_for(start(client))).text
    typed = "x;=cmd|' /C calc'!A0;\n \uff1d1+1\x00 and a ;@SUM(A1)"
    assert client.post("/study", data={**answer_for(page), "justification": typed}).status_code == 200
    ctx = client.app.state.context
    export_study(ctx.db, ctx.study, tmp_path / "export")
    with (tmp_path / "export" / "long.csv").open(newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    for row in rows:
        for cell in row.values():
            assert_safe(cell)
    (answer,) = [row["answer"] for row in rows if row["question"] == "justification"]
    assert restore(answer) == typed
    book = json.loads((tmp_path / "export" / "codebook.json").read_text())
    assert "restore" in book["neutralised_cells"] and "U+2400" in book["neutralised_cells"]
