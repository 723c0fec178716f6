"""Typeset the PDF report with fpdf2. Everything it prints is computed elsewhere and passed in."""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib
import pandas as pd
from fpdf import FPDF
from fpdf.fonts import FontFace
from PIL import Image

from analysis.claims import NOT_SUPPORTED, SUPPORTED, TIE, ClaimResult, verdict_sentence
from analysis.labels import METRIC_LABELS, SCENARIOS, VEHICLE_PARAMETERS, fmt, model_label, parameter_label
from analysis.scenarios import PAPER_CV_RATIO
from analysis.sections import Section, write_pdf_section
from analysis.tables import CLOSE_NOTE, HEADLINE_METRICS, HEADLINE_SCENARIO, SAFE_COLLISIONS

# matplotlib ships DejaVu: embedding it makes any Unicode in configs or labels safe, unlike the
# latin-1 core fonts.
_FONT_DIR = Path(matplotlib.get_data_path()) / "fonts" / "ttf"
SECTION_TITLES = ("Data used", "Environment and scenarios", "Average speed", "Lane changes", "Overtakes",
                  "Test results", "The paper's claims", "Discussion", "Appendix: configuration and commits")
# The space after a paragraph or a bullet list, in mm (`para_height` counts it in).
BLOCK_GAP_MM = 1.5
VERDICT_COLOURS = {SUPPORTED: (46, 147, 60), NOT_SUPPORTED: (209, 73, 91), TIE: (90, 90, 90)}


@dataclass
class ReportInputs:
    """What the report shows; built by `analysis.pipeline`."""

    tracking_uri: str
    experiment: str
    git_commits: list[str]
    seed_counts: pd.DataFrame  # model x scenario
    train_seeds: dict[str, int]
    notes: list[str]  # data coverage notes (dropped runs, missing baselines)
    figures: dict[str, Path]  # name -> PNG
    training_numbers: dict[str, pd.DataFrame]  # figure name -> table rows (strings)
    env_scalars: list[tuple[str, str]]
    vehicle_types: pd.DataFrame | None
    env_source: str
    pictures_note: str | None
    test_grids: dict[str, pd.DataFrame]  # metric -> model x scenario cell strings
    paper_table: pd.DataFrame
    aggregate: pd.DataFrame  # already formatted strings
    beating: pd.DataFrame  # model x scenario 'k of n': seeds beating the human-driven host safely
    claims: list[ClaimResult]
    discussion: list[str]
    configs: dict[str, list[tuple[str, str, str]]]  # model -> (key, value in its runs, default) that differ
    train_keys: list[str] = field(default_factory=list)  # of the training runs
    git_dirty: str = ""  # "true"/"false"/"mixed" from the runs' git_dirty tags
    scenario_mix: pd.DataFrame | None = None  # scenario x NCV/AHV/CHV, as the evaluation runs logged it
    scale: list[str] = field(default_factory=list)  # one line per preset: steps, images, checkpoint, episodes
    headline: pd.DataFrame | None = None  # tables.headline: return and collisions per host, scenario 3 and mean
    intervals: str = ""  # the interval method and its measured coverage
    configs_note: str = ""  # what the configs are compared with
    smoke: bool = False  # made with the smoke preset: not a result
    source: str = ""  # where the data came from, as the cover names it (no machine path for a bundle)
    config_runs: dict[str, str] = field(default_factory=dict)  # model -> which run its config is from
    sections: list[Section] = field(default_factory=list)  # after the claims: crash anatomy, on equal terms


SHARED_CONFIG = "every model"  # the appendix's entry for settings all models' runs share

SMOKE_BANNER = ("SMOKE RUN: NOT A RESULT. The smoke preset trains for a few hundred steps to prove that the "
                "pipeline runs end to end; its numbers, figures and verdicts say nothing about the paper.")


class _Pdf(FPDF):
    smoke = False

    def footer(self) -> None:
        self.set_y(-12)
        self.set_font("DejaVu", size=8)
        self.set_text_color(*((200, 30, 30) if self.smoke else (120, 120, 120)))
        what = "smoke run: not a result" if self.smoke else "hgm_repro reproduction report"
        self.cell(0, 6, f"{what}  -  page {self.page_no()}", align="C")
        self.set_text_color(0)


class ReportWriter:
    """Small layout helpers over fpdf2 so the section code reads top to bottom."""

    def __init__(self) -> None:
        self.pdf = _Pdf(format="A4")
        self.pdf.set_margins(16, 16, 16)
        self.pdf.set_auto_page_break(True, margin=18)
        self.pdf.add_font("DejaVu", "", str(_FONT_DIR / "DejaVuSans.ttf"))
        self.pdf.add_font("DejaVu", "B", str(_FONT_DIR / "DejaVuSans-Bold.ttf"))
        self.pdf.add_font("DejaVu", "I", str(_FONT_DIR / "DejaVuSans-Oblique.ttf"))
        self.pdf.add_font("DejaVuMono", "", str(_FONT_DIR / "DejaVuSansMono.ttf"))
        self.pdf.set_font("DejaVu", size=10)
        self.section_no = 0

    @property
    def width(self) -> float:
        return self.pdf.w - self.pdf.l_margin - self.pdf.r_margin

    def section(self, title: str, new_page: bool = True) -> None:
        # The table of contents placeholder already breaks the page: no blank page after it.
        if new_page and self.pdf.get_y() > self.pdf.t_margin + 1:
            self.pdf.add_page()
        self.section_no += 1
        self.pdf.start_section(f"{self.section_no}. {title}")
        self.pdf.set_font("DejaVu", "B", 15)
        self.pdf.cell(0, 10, f"{self.section_no}. {title}", new_x="LMARGIN", new_y="NEXT")
        self.pdf.set_font("DejaVu", size=10)

    def heading(self, text: str, keep_mm: float = 30) -> None:
        self.space(2)
        self.keep(keep_mm)
        self.pdf.set_font("DejaVu", "B", 11)
        self.pdf.multi_cell(0, 6, text, align="L", new_x="LMARGIN", new_y="NEXT")
        self.pdf.set_font("DejaVu", size=10)

    def para(self, text: str, size: float = 10, italic: bool = False) -> None:
        self.pdf.set_font("DejaVu", "I" if italic else "", size)
        self.pdf.multi_cell(0, size * 0.5, text, new_x="LMARGIN", new_y="NEXT")
        self.pdf.set_font("DejaVu", size=10)
        self.space(BLOCK_GAP_MM)

    def para_height(self, text: str, size: float = 10) -> float:
        """The height `para(text, size)` takes, without drawing it."""
        self.pdf.set_font("DejaVu", size=size)
        height = self.pdf.multi_cell(0, size * 0.5, text, dry_run=True, output="HEIGHT")
        self.pdf.set_font("DejaVu", size=10)
        return height + BLOCK_GAP_MM

    def bullets(self, items: Sequence[str], size: float = 9.5) -> None:
        self.pdf.set_font("DejaVu", size=size)
        for item in items:
            self.pdf.set_x(self.pdf.l_margin + 3)
            self._bullet(item, size, new_x="LMARGIN", new_y="NEXT")
        self.pdf.set_font("DejaVu", size=10)
        self.space(BLOCK_GAP_MM)

    def _bullet(self, item: str, size: float, **cell: object) -> object:
        """One bullet as `bullets` sets it (indented 3 mm), drawn or, with dry_run, only measured."""
        return self.pdf.multi_cell(self.width - 3, size * 0.5, f"- {item}", align="L", **cell)

    def bullets_height(self, items: Sequence[str], size: float) -> float:
        """The height `bullets(items, size)` takes, without drawing it."""
        self.pdf.set_font("DejaVu", size=size)
        height = sum(self._bullet(item, size, dry_run=True, output="HEIGHT") for item in items)
        self.pdf.set_font("DejaVu", size=10)
        return height

    def fitting_size(self, items: Sequence[str], size: float, smallest: float) -> float:
        """The largest font size from `size` down to `smallest`, in half points, at which `items` fit in what is
        left of the page; `smallest` where none does (they then run onto the next page)."""
        left = self.pdf.h - self.pdf.b_margin - self.pdf.get_y()
        while size > smallest and self.bullets_height(items, size) > left:
            size -= 0.5
        return max(size, smallest)

    def space(self, mm: float) -> None:
        self.pdf.ln(mm)

    def keep(self, mm: float) -> None:
        """Start a new page unless `mm` of height is left (keeps headings with what follows)."""
        if self.pdf.get_y() + mm > self.pdf.h - self.pdf.b_margin:
            self.pdf.add_page()

    def image_height(self, path: Path, width: float | None = None) -> float:
        w = min(width or self.width, self.width)
        with Image.open(path) as im:
            return w * im.height / im.width

    def image(self, path: Path, width: float | None = None, caption: str | None = None) -> None:
        w = min(width or self.width, self.width)
        h = self.image_height(path, width)
        self.keep(h + 10)
        x = self.pdf.l_margin + (self.width - w) / 2
        self.pdf.image(str(path), x=x, w=w)
        if caption:
            self.para(caption, size=8.5, italic=True)

    def table(self, rows: list[list[str]], col_widths: Sequence[float] | None = None, size: float = 8,
              align: str = "CENTER", first_col_left: bool = True, mono: bool = False,
              headings: bool = True) -> None:
        """A table whose first row is the heading; cells may hold two lines separated by a newline."""
        self.pdf.set_font("DejaVuMono" if mono else "DejaVu", size=size)
        # Room for the heading row and a first row; a heading() before the table asks for more.
        self.keep(20)
        aligns = ["LEFT" if (first_col_left and i == 0) else align for i in range(len(rows[0]))]
        with self.pdf.table(col_widths=col_widths, text_align=aligns, line_height=size * 0.48,
                            headings_style=FontFace(emphasis="BOLD", fill_color=(230, 234, 240)),
                            padding=(0.8, 1.2), width=self.width, first_row_as_headings=headings) as table:
            for row in rows:
                r = table.row()
                for cell in row:
                    r.cell(str(cell))
        self.pdf.set_font("DejaVu", size=10)
        self.space(3)

    def frame_table(self, frame: pd.DataFrame, index_name: str, size: float = 8,
                    first_width: float = 2.0) -> None:
        rows = [[index_name, *[str(c) for c in frame.columns]]]
        rows += [[str(i), *[str(v) for v in r]] for i, r in zip(frame.index, frame.to_numpy(), strict=True)]
        self.table(rows, col_widths=[first_width] + [1.0] * len(frame.columns), size=size)

    def verdict(self, result: ClaimResult) -> None:
        self.keep(30)
        colour = VERDICT_COLOURS.get(result.verdict, (200, 140, 20))  # inconclusive: amber
        self.pdf.set_font("DejaVu", "B", 10.5)
        self.pdf.multi_cell(0, 5.5, f"Claim {result.number}. {result.statement}", align="L",
                            new_x="LMARGIN", new_y="NEXT")
        self.pdf.set_text_color(*colour)
        self.pdf.cell(0, 6, f"Verdict: {result.verdict.upper()}", new_x="LMARGIN", new_y="NEXT")
        self.pdf.set_text_color(0)
        self.para(f"Rule: {result.rule}", size=8.5, italic=True)
        self.bullets([c.text() for c in result.comparisons] + result.notes, size=8.5)

    def save(self, path: Path) -> Path:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.pdf.output(str(path))
        return path


def claim_numbers(claims: Sequence[ClaimResult], verdict: str) -> str:
    """'claims 1, 2 and 4', 'claim 7' or 'none': the numbers, never a count."""
    numbers = [str(r.number) for r in claims if r.verdict == verdict]
    if not numbers:
        return "none"
    if len(numbers) == 1:
        return f"claim {numbers[0]}"
    return f"claims {', '.join(numbers[:-1])} and {numbers[-1]}"


def _headline_cell(row: pd.Series, metric: str, where: str) -> str:
    n = row[f"{metric}/{where}/n"]
    return fmt_estimate(row[f"{metric}/{where}/point"], row[f"{metric}/{where}/low"], row[f"{metric}/{where}/high"],
                        0 if pd.isna(n) else int(n), metric)


def headline_rows(headline: pd.DataFrame) -> list[list[str]]:
    """The headline table as rows of text, heading row first (shared by the PDF and results.md)."""
    head = ["Host", "Seeds"]
    for metric in HEADLINE_METRICS:
        what = METRIC_LABELS[metric].replace(" per episode", "")
        head += [f"{what}, scenario {HEADLINE_SCENARIO}", f"{what}, mean of scenarios"]
    rows = [head]
    for _, row in headline.iterrows():
        n = row[f"{HEADLINE_METRICS[0]}/mean/n"]
        rows.append([model_label(row["model"], short=True), "-" if pd.isna(n) else str(int(n)),
                     *[_headline_cell(row, m, w) for m in HEADLINE_METRICS for w in ("scenario", "mean")]])
    return rows


HEADLINE_NOTE = (f"Per test episode: mean over seeds [its 95 % interval over seeds]. Scenario "
                 f"{HEADLINE_SCENARIO} has the training traffic's mix (CV ratio 0.5); the mean of scenarios averages "
                 "each seed over scenarios 1-5 first. An episode ends at its time limit or at the host's first "
                 "collision, so collisions per episode is the share of episodes that end in a crash, and its "
                 "interval is cut to [0, 1].")


def _claims_table(w: ReportWriter, claims: Sequence[ClaimResult]) -> None:
    """One row per claim: the claim, its verdict in colour, and the sentence that says what decides it."""
    w.pdf.set_font("DejaVu", size=7.5)
    w.keep(20)
    with w.pdf.table(col_widths=[2.9, 1.0, 4.3], text_align=["LEFT", "CENTER", "LEFT"], line_height=3.5,
                     headings_style=FontFace(emphasis="BOLD", fill_color=(230, 234, 240)), padding=(0.8, 1.2),
                     width=w.width) as table:
        head = table.row()
        for text in ("The paper's claim", "Verdict", "What decides it"):
            head.cell(text)
        for result in claims:
            row = table.row()
            row.cell(f"{result.number}. {result.statement}")
            row.cell(result.verdict, style=FontFace(emphasis="BOLD",
                                                    color=VERDICT_COLOURS.get(result.verdict, (200, 140, 20))))
            row.cell(verdict_sentence(result))
    w.pdf.set_font("DejaVu", size=10)
    w.space(2)


def _title_page(w: ReportWriter, inp: ReportInputs) -> None:
    """Page 1 answers: what the hosts earn and how often they crash, each claim's verdict, the scale."""
    pdf = w.pdf
    pdf.add_page()
    pdf.set_font("DejaVu", "B", 16)
    pdf.multi_cell(0, 8, "Reproduction report" + (" (smoke run)" if inp.smoke else ""), align="C",
                   new_x="LMARGIN", new_y="NEXT")
    pdf.set_font("DejaVu", "", 10.5)
    pdf.multi_cell(0, 5.5, "Deep RL driving decisions in heterogeneous highway traffic with a Hyper-Grid "
                           "Matrix (Bai et al.): our runs against the paper's claims", align="C",
                   new_x="LMARGIN", new_y="NEXT")
    pdf.ln(3)
    if inp.smoke:
        pdf.set_fill_color(253, 226, 226)
        pdf.set_text_color(170, 20, 20)
        pdf.set_font("DejaVu", "B", 10)
        pdf.multi_cell(0, 5.5, SMOKE_BANNER, align="C", fill=True, border=1, padding=2, new_x="LMARGIN",
                       new_y="NEXT")
        pdf.set_text_color(0)
        pdf.set_fill_color(255)  # tables fill their cells with the current colour
        pdf.set_font("DejaVu", size=10)
        pdf.ln(2)
    if inp.headline is not None and not inp.headline.empty:
        w.heading("What each host earns and how often it crashes", keep_mm=60)
        w.table(headline_rows(inp.headline), col_widths=[1.4, 0.55, 1.3, 1.3, 1.3, 1.3], size=7.5)
        pdf.set_y(pdf.get_y() - 2)
        w.para(HEADLINE_NOTE, size=7.5, italic=True)
    w.heading("The paper's claims", keep_mm=40)
    _claims_table(w, inp.claims)
    if inp.intervals:
        w.para(inp.intervals, size=7.5, italic=True)
    # The heading says what the scale means, so that the lines under it fit the first page.
    w.heading("Scale of these runs: every number and verdict holds at this scale only", keep_mm=15)
    # Each rung of the scale ladder adds lines here: they shrink, to 6.5 pt at the least, before they leave page 1.
    scale = inp.scale or ["Scale unknown."]
    w.bullets(scale, size=w.fitting_size(scale, 7.5, smallest=6.5))
    w.space(2)
    info = [
        ["Generated", dt.datetime.now().strftime("%Y-%m-%d %H:%M")],
        ["Data", inp.source or inp.tracking_uri],
        ["Experiment", inp.experiment],
        ["Git commit(s) of the runs", "\n".join(inp.git_commits) or "not recorded"],
        ["Uncommitted changes (git_dirty)", inp.git_dirty or "not recorded"],
        ["Training configurations", f"{len(inp.train_keys)} train_keys of the learned models' training runs "
                                    "(listed in the appendix)" if inp.train_keys else "no training runs"],
    ]
    w.table(info, col_widths=[1.0, 2.2], size=7.5, align="LEFT", headings=False)
    pdf.add_page()
    pdf.insert_toc_placeholder(_toc, pages=1)


def _toc(pdf: FPDF, outline: list) -> None:
    pdf.set_x(pdf.l_margin)
    pdf.set_font("DejaVu", "B", 15)
    pdf.cell(0, 10, "Contents", new_x="LMARGIN", new_y="NEXT")
    pdf.set_font("DejaVu", size=11)
    for entry in outline:
        pdf.cell(0, 7, f"{entry.name}", new_x="END", new_y="LAST", link=pdf.add_link(page=entry.page_number))
        pdf.set_x(pdf.w - pdf.r_margin - 15)
        pdf.cell(15, 7, str(entry.page_number), align="R", new_x="LMARGIN", new_y="NEXT")


def _data_section(w: ReportWriter, inp: ReportInputs) -> None:
    w.section(SECTION_TITLES[0])
    w.para("Seeds per method and test scenario in the store (0 = no run). Each cell is one evaluation "
           "run per seed; learned methods are evaluated from the checkpoint trained with that seed.")
    if inp.seed_counts.empty:
        w.para("The store holds no evaluation runs.")
    else:
        frame = inp.seed_counts.copy()
        frame.index = [model_label(m) for m in frame.index]
        frame.columns = [f"Sc. {c}" if c in SCENARIOS else str(c) for c in frame.columns]
        w.frame_table(frame, "Method", size=8.5, first_width=2.6)
    if inp.train_seeds:
        w.para("Training runs (seeds) per method: " + ", ".join(f"{model_label(m, True)} {n}"
                                                                for m, n in inp.train_seeds.items()) + ".")
    else:
        w.para("No training runs in the store: the training figures are left out.")
    if inp.notes:
        w.heading("Coverage notes")
        w.bullets(inp.notes)


def _environment_section(w: ReportWriter, inp: ReportInputs) -> None:
    w.section(SECTION_TITLES[1])
    w.para(f"Simulator parameters ({inp.env_source}).", size=9)
    half = (len(inp.env_scalars) + 1) // 2
    left, right = inp.env_scalars[:half], inp.env_scalars[half:]
    rows = [["Parameter (unit)", "Value", "Parameter (unit)", "Value"]]
    for i in range(half):
        r = right[i] if i < len(right) else ("", "")
        rows.append([parameter_label(left[i][0]), left[i][1], parameter_label(r[0]) if r[0] else "", r[1]])
    if inp.env_scalars:
        w.table(rows, col_widths=[2.2, 1.0, 2.2, 1.0], size=7.5)
    if inp.vehicle_types is not None and not inp.vehicle_types.empty:
        w.heading("Vehicle types (paper Table 1 plus the sizes and gaps it leaves open)")
        w.para("HV: the host; CHV / AHV: conservative / aggressive human-driven vehicles; NCV: connected "
               "vehicles.", size=8.5)
        # One row per parameter, with its meaning and unit: parameter names as column headings
        # would be split mid-word.
        types = inp.vehicle_types.T
        types.index = [VEHICLE_PARAMETERS.get(str(k), str(k)) for k in types.index]
        w.frame_table(types, "Parameter", size=7.5, first_width=3.2)
    w.heading("Test scenarios (paper Table 5)")
    mix = inp.scenario_mix
    if mix is not None and not mix.empty:
        w.para("The traffic mix each scenario's evaluation runs logged (scenario.ratios).", size=8.5)
        names = [s for s in (*SCENARIOS, *sorted(set(mix.index) - set(SCENARIOS))) if s in mix.index]
        rows = [["Scenario", *names], *[[f"{t} ratio", *[f"{mix.loc[s, t]:.3f}" for s in names]]
                                        for t in ("NCV", "AHV", "CHV")]]
    else:  # runs that logged no mix: the paper's table
        w.para("The runs logged no traffic mix: the paper's Table 5.", size=8.5)
        rows = [["Scenario", *PAPER_CV_RATIO], ["NCV ratio", *[f"{v:.3f}" for v in PAPER_CV_RATIO.values()]],
                ["AHV ratio", *[f"{(1 - v) / 2:.3f}" for v in PAPER_CV_RATIO.values()]],
                ["CHV ratio", *[f"{(1 - v) / 2:.3f}" for v in PAPER_CV_RATIO.values()]]]
    w.table(rows, size=8.5)
    # The heading stays on the page of its figure.
    w.heading("What the host sees in each scenario",
              keep_mm=w.image_height(inp.figures["scenes"]) + 30 if "scenes" in inp.figures else 30)
    if "scenes" in inp.figures:
        w.image(inp.figures["scenes"], caption="Top: the host's front camera. Bottom: the Hyper-Grid Matrix in "
                "metres around the host (forward is up; colours scaled to the speed limits: red = faster than the "
                "mid speed (v_max+v_min)/2, blue = slower, white = mid speed or empty cell). Only connected "
                "vehicles appear in the HGM, so it fills up as the CV ratio grows.")
    else:
        w.para(inp.pictures_note or "Pictures not available.", size=9, italic=True)


def _training_section(w: ReportWriter, inp: ReportInputs, index: int, name: str, what: str) -> None:
    w.section(SECTION_TITLES[index])
    if name not in inp.figures:
        w.para(f"No training curves of {what} in the store.")
        return
    w.image(inp.figures[name], caption=f"{what.capitalize()} against environment steps: line = mean over "
            "seeds of each method's binned curve, band = 95 % t interval over seeds (no band with one seed). "
            "Dashed: evaluation means of the non-learning hosts, for reference. A variant trained for longer has "
            "its own panel, so the paper's three methods keep their own step range.")
    numbers = inp.training_numbers.get(name)
    if numbers is not None and not numbers.empty:
        w.heading("Per-seed summaries (mean over seeds, 95 % interval)")
        rows = [list(numbers.columns)] + numbers.astype(str).to_numpy().tolist()
        w.table(rows, col_widths=[1.6] + [1.0] * (len(numbers.columns) - 1), size=8)


def _test_section(w: ReportWriter, inp: ReportInputs) -> None:
    w.section(SECTION_TITLES[5])
    w.heading("Table 6 (ours): mean test episode return per method and scenario")
    w.para("Mean over seeds with its 95 % interval below it. Our score is the mean episode return "
           "(Algorithm 2's reward summed over an episode); the paper does not say what its score is.", size=9)
    grid = inp.test_grids.get("episode_return")
    if grid is None or grid.empty:
        w.para("No evaluation runs with an episode return in the store.")
    else:
        _grid_table(w, grid)
    w.heading("Table 6 as printed in the paper (score, units not stated)")
    w.frame_table(inp.paper_table.astype(str), "Method (paper)", size=8.5, first_width=1.6)
    if not inp.aggregate.empty:
        w.heading("Across scenarios: mean, IQM and probability of improvement of the episode return")
        w.para("Mean = each seed averaged over the scenarios, then the mean over seeds with its t interval; "
               "IQM = interquartile mean of all (scenario, seed) scores; P(Proposed > X) = chance that a random "
               "seed of Proposed beats a random seed of X in the same scenario, averaged over scenarios (Agarwal "
               "et al. 2021). IQM and P are points: no interval for them has been shown to cover at five seeds.",
               size=8.5)
        rows = [list(inp.aggregate.columns)] + inp.aggregate.astype(str).to_numpy().tolist()
        w.table(rows, col_widths=[1.7, 0.8, 1.4, 1.4, 1.4], size=8)
    if not inp.beating.empty:
        w.heading(f"Seeds on which a host beats the human-driven host (more return, under {SAFE_COLLISIONS:g} "
                  "collisions per episode)", keep_mm=_grid_table_height(inp.beating))
        w.para("Each seed's test return against the human-driven host's on the same seed and scenario (the same "
               "traffic): a mean over seeds can hide that only some seeds drive better.", size=8.5)
        frame = inp.beating.copy()
        frame.index = [model_label(m, short=True) for m in frame.index]
        frame.columns = [f"Scenario {c}" if c in SCENARIOS else str(c) for c in frame.columns]
        w.frame_table(frame, "Method", size=8, first_width=1.3)
        if frame.apply(lambda col: col.str.contains("close")).any().any():
            w.para(CLOSE_NOTE, size=8)
    if "fig_test_results" in inp.figures:
        w.image(inp.figures["fig_test_results"], caption="Every test metric per scenario: mean over seeds and "
                "95 % t interval over seeds; scenario k has CV ratio (k-1)/4.")
    for metric, grid in inp.test_grids.items():
        if metric == "episode_return" or grid.empty:
            continue
        # Keep the heading on the page of its table.
        w.heading(f"{METRIC_LABELS.get(metric, metric)}: mean and 95 % interval over seeds",
                  keep_mm=_grid_table_height(grid))
        _grid_table(w, grid)


def _grid_table_height(grid: pd.DataFrame) -> float:
    # Heading text, the table's heading row, then two-line cells of about 9.5 mm each.
    return 16.0 + 9.5 * len(grid)


def _grid_table(w: ReportWriter, grid: pd.DataFrame) -> None:
    frame = grid.copy()
    frame.index = [model_label(m, short=True) for m in frame.index]
    frame.columns = [f"Scenario {c}" if c in SCENARIOS else str(c) for c in frame.columns]
    w.frame_table(frame, "Method", size=8, first_width=1.3)


def _claims_section(w: ReportWriter, inp: ReportInputs) -> None:
    w.section(SECTION_TITLES[6])
    w.para("Each claim is split into signed differences (positive = what the paper says), each with its 95 % "
           "Student-t interval over seeds. A difference supports the claim when its interval lies above 0, "
           "contradicts it when the interval lies below 0, and is a tie when the interval covers 0; with fewer "
           "than 3 seeds it is undecided. A claim needs all its differences to hold; one contradiction makes it "
           "not supported; otherwise a tie makes it a tie.", size=9)
    rows = [["Claim", "Statement", "Verdict"]] + [[str(r.number), r.statement, r.verdict] for r in inp.claims]
    w.table(rows, col_widths=[0.5, 5.0, 1.2], size=8.5, align="LEFT")
    for result in inp.claims:
        w.verdict(result)


def _appendix(w: ReportWriter, inp: ReportInputs) -> None:
    w.section(SECTION_TITLES[8])
    w.para("Git commit(s) recorded on the runs used: " + (", ".join(inp.git_commits) or "none recorded") + ".")
    if inp.train_keys:
        w.para("Training configurations (train_key of each training run): " + ", ".join(inp.train_keys) + ".",
               size=8)
    if not inp.configs:
        w.para("No resolved config.yaml artifact was found on the evaluation runs.")
        return
    w.heading("Settings that differ from the defaults")
    if inp.configs_note:
        w.para(inp.configs_note, size=8.5)
    for model, rows in inp.configs.items():
        which = f" ({inp.config_runs[model]})" if model in inp.config_runs else ""
        title = "Every model's runs" if model == SHARED_CONFIG else model_label(model) + which
        if not rows:
            w.para(f"{title}: nothing else differs.", size=8.5)
            continue
        w.pdf.set_font("DejaVu", "B", 9)
        w.keep(12 + 4.5 * len(rows))
        w.pdf.multi_cell(0, 5, title, new_x="LMARGIN", new_y="NEXT")
        w.table([["Setting", "In these runs", "Default"], *[list(r) for r in rows]], col_widths=[2.2, 1.6, 1.6],
                size=8, align="LEFT")


def write_report(inp: ReportInputs, path: Path) -> Path:
    """Write the whole report to `path`."""
    w = ReportWriter()
    w.pdf.smoke = inp.smoke
    _title_page(w, inp)
    _data_section(w, inp)
    _environment_section(w, inp)
    _training_section(w, inp, 2, "fig5_speed", "average speed")
    _training_section(w, inp, 3, "fig6_lane_changes", "lane changes per episode")
    _training_section(w, inp, 4, "fig7_overtakes", "overtakes per episode")
    _test_section(w, inp)
    _claims_section(w, inp)
    for extra in inp.sections:
        write_pdf_section(w, extra)
    w.section(SECTION_TITLES[7])
    if inp.smoke:
        w.para("These are smoke runs: what follows is not a result.", size=9, italic=True)
    for para in inp.discussion:
        w.para(para)
    _appendix(w, inp)
    return w.save(path)


def fmt_estimate(point: float, low: float, high: float, n: int, metric: str = "", digits: int | None = None) -> str:
    """'mean [low, high]', or 'mean (1 seed, no CI)', or 'n/a'."""
    if n == 0:
        return "n/a"
    if n < 2:
        return f"{fmt(point, metric, digits)} (1 seed, no CI)"
    return f"{fmt(point, metric, digits)} [{fmt(low, metric, digits)}, {fmt(high, metric, digits)}]"
