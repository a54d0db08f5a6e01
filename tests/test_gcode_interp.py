"""The one G-code interpreter (`fivebar_host.gcode`) on its own: words and GRBL's error codes,
the modal state (units, distances, offsets, G28, program end), arcs read the GRBL way and the
file reader's way (`Rules`)."""

from __future__ import annotations

import math
from itertools import pairwise

import pytest

from fivebar_host.bridge.policy import RULES as GRBL
from fivebar_host.gcode import (
    Action,
    GcodeError,
    ModalState,
    Move,
    Policy,
    ProgramFlow,
    Rules,
    Word,
    execute,
    parse,
    preparse,
    strip_file,
)
from fivebar_host.gcode.arcs import chords
from fivebar_host.toolpath.gcode import RULES as FILE


def run(lines: list[str], rules: Rules = GRBL, state: ModalState | None = None
        ) -> tuple[ModalState, list[Action]]:
    """Execute lines (pre-parsed as GRBL does) from `state`; the actions of the last one."""
    st = state or ModalState()
    acts: list[Action] = []
    for line in lines:
        st, acts = execute(st, parse(preparse(line), rules.strict), rules)
    return st, acts


def move(lines: list[str], rules: Rules = GRBL, state: ModalState | None = None
         ) -> tuple[ModalState, Move]:
    """`run`, whose last line makes one move."""
    st, (mv,) = run(lines, rules, state)
    assert isinstance(mv, Move)
    return st, mv


def code_of(text: str, strict: bool = True) -> int:
    with pytest.raises(GcodeError) as e:
        parse(text, strict)
    return e.value.code


def test_preparse_and_strip_file() -> None:
    assert preparse("g1 x1 (a;b) y2 ; c") == "G1X1Y2"
    assert preparse("G1 X1 (unclosed y2") == "G1X1"
    with pytest.raises(GcodeError) as e:
        preparse("G0 " + "X1.0000" * 12)
    assert e.value.code == 11
    assert strip_file("N10 G1 X1 (move) Y2 *57 ; c") == "N10 G1 X1   Y2"
    assert strip_file(" % ") == ""
    with pytest.raises(GcodeError, match="unbalanced"):
        strip_file("G1 (a")


@pytest.mark.parametrize(("text", "code"), [
    ("1G0", 1), ("X", 2), ("G0X1.2.3", 1), ("G0G1X1", 21), ("X1X2", 25), ("G1.5", 23),
    ("G38.2", 20), ("M6", 20), ("M3.5", 23), ("N1.5", 27), ("N-1", 4), ("T300", 38),
    ("F-1", 4), ("Q5", 20), ("X" + "9" * 400, 2),
])
def test_words_refused_with_grbls_code(text: str, code: int) -> None:
    assert code_of(text) == code


def test_unreadable_text_is_quoted_before_any_other_check() -> None:
    with pytest.raises(GcodeError, match=r"cannot read 'X\$'"):
        parse("Q5 G1 X$", strict=False)


def test_lenient_words_keep_every_command_and_skip_n() -> None:
    b = parse("N10 G20 G21 g 1 X 5 m3 M5", strict=False)
    assert b.g == {"units": 210, "motion": 10} and b.gcodes == [200, 210, 10]
    assert b.m == {"spindle": 5} and b.values == {"X": 5.0}
    assert b.words[3] == Word("G", 1.0, "g1")
    assert parse("G1.04", strict=False).g == {"motion": 10}  # a tenth, rounded


def test_policy_sees_the_other_words_in_order() -> None:
    seen: list[str] = []

    def check(w: Word) -> None:
        seen.append(w.text)
        if w.letter == "Q":
            raise GcodeError(20, f"no {w.text}", w.text)

    with pytest.raises(GcodeError) as e:
        parse("G1 X1 Q2 Y3 Q4", False, Policy(frozenset("XY"), check))
    assert seen == ["G1", "Q2"] and e.value.word == "Q2"


def test_units_distances_and_work_offsets() -> None:
    st, mv = move(["G10 L2 P2 X5 Y95", "G55 G20 G91 G1 X1 Y1 F10"])
    assert mv.end == pytest.approx((25.4, 25.4, 0.0))
    assert st.feed == pytest.approx(254.0) and st.wcs == 1
    st, mv = move(["G90 G1 X1 Y0"], state=st)  # G55 + inches: (5 + 25.4, 95)
    assert mv.end == pytest.approx((30.4, 95.0, 0.0))
    st, _ = run(["G21 G92 X0 Y0"], state=st)
    assert st.work_offset() == pytest.approx((30.4, 95.0, 0.0))
    st, mv = move(["G53 G0 X1 Y2"], state=st)
    assert mv.rapid and mv.end == (1.0, 2.0, 0.0)


def test_execute_leaves_its_state_and_refuses_as_grbl() -> None:
    st = ModalState()
    with pytest.raises(GcodeError) as e:
        execute(st, parse("G1X5", True), GRBL)
    assert e.value.code == 22 and st == ModalState()
    for line, code in (("G80 X1", 31), ("G0 X1 I2", 36), ("G2 Z1 I1 F9", 32), ("G4", 28),
                       ("G10 L2 P7 X1", 29), ("G92 X1 G1", 24), ("G53 G2 X1 Y1 I1", 30)):
        with pytest.raises(GcodeError) as e:
            execute(st, parse(preparse(line), True), GRBL)
        assert e.value.code == code, line


def test_home_and_program_end() -> None:
    st = ModalState(g28=(20.0, 120.0, 0.0))
    st, acts = run(["G28 X5"], state=st)
    assert [a.end for a in acts if isinstance(a, Move)] == [(5.0, 0.0, 0.0), (20.0, 0.0, 0.0)]
    st, acts = run(["G91 M3 S500 G1 X1 F100 M2"], state=st)
    assert isinstance(acts[-1], ProgramFlow) and acts[-1].code == 2
    assert (st.distance, st.spindle, st.motion, st.s) == (900, 5, 0, 500.0)
    assert st.position == (21.0, 0.0, 0.0)


def test_the_file_reader_reads_leniently() -> None:
    st = ModalState(motion=800, feed=math.nan)
    with pytest.raises(GcodeError, match="coordinates before any G0/G1/G2/G3"):
        execute(st, parse("X1", False), FILE)
    st, (mv,) = execute(st._replace(motion=20), parse("I-5", False), FILE)
    assert isinstance(mv, Move) and mv.exact_arc().sweep == pytest.approx(-2 * math.pi)
    assert math.isnan(mv.feed)


@pytest.mark.parametrize(("off_mm", "grbl_ok", "file_ok"), [
    (0.004, True, True), (0.4, True, True), (0.6, False, True), (1.2, False, False)])
def test_arc_end_tolerance_grbl_and_file(off_mm: float, grbl_ok: bool, file_ok: bool) -> None:
    """r = 1000 mm: GRBL allows 0.1 % of r up to 0.5 mm, the file reader 0.1 % of r."""
    line = f"G2 X{2000 + off_mm} Y0 I1000 J0 F100"
    for rules, ok in ((GRBL, grbl_ok), (FILE, file_ok)):
        _, mv = move([line], rules)
        if ok:
            assert mv.exact_arc().radius == pytest.approx(1000.0)
        else:
            with pytest.raises(GcodeError, match="off the circle"):
                mv.exact_arc()


def test_r_arcs_and_chords() -> None:
    for code, r, centre in (("G3", 5, (0, 0)), ("G2", 5, (5, 5)), ("G3", -5, (5, 5))):
        _, mv = move(["G0 X5 Y0", f"{code} X0 Y5 R{r} F100"])
        arc = mv.exact_arc()
        assert (arc.cx, arc.cy) == pytest.approx(centre, abs=1e-12)
        pts = mv.points(0.01)
        assert pts[-1] == (0.0, 5.0)
        mid = [((a[0] + b[0]) / 2, (a[1] + b[1]) / 2) for a, b in pairwise(pts)]
        assert all(5 - math.hypot(x - arc.cx, y - arc.cy) <= 0.01 for x, y in mid)
    _, mv = move(["G0 X0 Y0", "G2 X10.000004 R5 F100"])
    with pytest.raises(GcodeError) as e:
        mv.exact_arc()  # GRBL: R must reach half the chord; the file reader has slack
    assert e.value.code == 34
    _, mv = move(["G0 X0 Y0", "G2 X10.000004 R5"], FILE, ModalState(feed=math.nan))
    assert mv.exact_arc().radius == 5


def test_full_circle_chords_end_where_they_start() -> None:
    _, mv = move(["G0 X5 Y0", "G3 X5 Y0 I-5 J0 F100"])
    arc = mv.exact_arc()
    assert arc.sweep == pytest.approx(2 * math.pi)
    pts = chords(arc, (5.0, 0.0), (5.0, 0.0), 0.001)
    assert len(pts) > 50 and pts[-1] == (5.0, 0.0)
