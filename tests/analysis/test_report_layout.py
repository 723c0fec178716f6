"""The report's layout helpers: the scale lines shrink to stay on page 1 (fast: a PDF in memory only)."""

from __future__ import annotations

from analysis.report import ReportWriter

LINE = ("The paper's steps (1M steps, Table 4's learner, 36x36x2), scenario 3, per episode (scale ladder): Proposed "
        "51.6 return, 0.321 collisions (2 of 5 seeds, no CI; 0 beat the human-driven host); Min 13.5 return, 1.000 "
        "collisions (2 of 5 seeds, no CI; 0 beat the human-driven host); Coordinate not run.")


def _writer_at(y: float) -> ReportWriter:
    w = ReportWriter()
    w.pdf.add_page()
    w.pdf.set_y(y)
    return w


def _height(items: list[str], size: float) -> float:
    return _writer_at(40).bullets_height(items, size)


def test_the_measured_height_is_the_drawn_height() -> None:
    w = _writer_at(40)
    height = w.bullets_height([LINE, LINE], 7.5)
    w.bullets([LINE, LINE], size=7.5)
    # bullets() adds 1.5 mm of space after the list.
    assert abs(w.pdf.get_y() - 40 - 1.5 - height) < 0.01
    assert height > 4 * 7.5 * 0.5 - 0.01  # each line wraps once at this width


def test_lines_shrink_to_fit_what_is_left_of_the_page() -> None:
    items = [LINE] * 4
    roomy = _writer_at(40)
    assert roomy.fitting_size(items, 7.5, smallest=6.5) == 7.5
    full_height = roomy.bullets_height(items, 7.5)
    bottom = roomy.pdf.h - roomy.pdf.b_margin
    # Room for the lines at 7 pt but not at 7.5 pt: they shrink by half a point and stay on the page.
    w = _writer_at(bottom - (full_height + _height(items, 7.0)) / 2)
    size = w.fitting_size(items, 7.5, smallest=6.5)
    assert size == 7.0
    w.bullets(items, size=size)
    assert w.pdf.page_no() == 1
    # No room even at the smallest size: the smallest, and the lines run onto the next page.
    tight = _writer_at(bottom - 5)
    assert tight.fitting_size(items, 7.5, smallest=6.5) == 6.5
    tight.bullets(items, size=6.5)
    assert tight.pdf.page_no() == 2
