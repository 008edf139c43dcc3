"""The HTML report: sections, embedded figures, findings computed from the data, self-containedness."""

from __future__ import annotations

import base64
import json
import shutil
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import uqgear.common
from uqgear.common.errors import UqgearError
from uqgear.report.findings import regime_findings
from uqgear.report.presentation import axis_label
from uqgear.report.study_report import REPORT_NAME, build_report, load_results, write_report
from uqgear.study.schema import load_study
from uqgear.study.variables import VARIABLES
from uqgear.uq.results import save_result

ROOT = Path(__file__).resolve().parent.parent
# the bundled studies, from the installed package (a wheel or sdist has no top-level studies/)
STUDIES = uqgear.common.bundled_file("study", "smoke").parent
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


class ReportParser(HTMLParser):
    """Collects sections (id, data-type), figures per section, table cells and external references."""

    def __init__(self) -> None:
        super().__init__()
        self.sections: list[dict] = []
        self.ids: set[str] = set()
        self.images: list[str] = []
        self.external: list[str] = []
        self.tags: set[str] = set()
        self.cells: list[str] = []
        self._in_cell = False

    def handle_starttag(self, tag, attrs):
        attributes = dict(attrs)
        self.tags.add(tag)
        if "id" in attributes:
            self.ids.add(attributes["id"])
        if tag == "section":
            self.sections.append({"id": attributes.get("id"), "type": attributes.get("data-type"), "images": []})
        if tag == "img":
            source = attributes.get("src", "")
            self.images.append(source)
            self.sections[-1]["images"].append(source)
        for name in ("src", "href"):
            value = attributes.get(name)
            if value is not None and not value.startswith(("data:", "#")):
                self.external.append(value)
        self._in_cell = tag in ("td", "th")

    def handle_data(self, data):
        if self._in_cell:
            self.cells.append(data.strip())

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self._in_cell = False


@pytest.fixture(scope="module")
def smoke_report(tmp_path_factory, smoke_study_run) -> tuple[Path, str]:
    """The smoke study's results (one run serves every test file, tests/conftest.py), and their report."""
    completed, results = smoke_study_run
    assert completed.returncode == 0, completed.stderr
    folder = tmp_path_factory.mktemp("report")
    for path in results.glob("*.nc"):
        shutil.copy2(path, folder)
    path = write_report(folder, dpi=60)
    return folder, path.read_text()


@pytest.fixture(scope="module")
def parsed(smoke_report) -> ReportParser:
    parser = ReportParser()
    parser.feed(smoke_report[1])
    return parser


def test_report_has_every_section(parsed):
    study = load_study(STUDIES / "smoke.yaml")
    for identifier in ("what-this-shows", "summary", "design", "uncertain", "versions", "findings", "caveats",
                       "study-text", "provenance", "summary-table", "design-table", "uncertain-table",
                       "versions-table"):
        assert identifier in parsed.ids, identifier
    analysis_sections = {s["id"]: s["type"] for s in parsed.sections if s["id"].startswith("analysis-")}
    assert analysis_sections == {f"analysis-{spec.name}": spec.type for spec in study.analyses}


# figures per analysis of the smoke study: simulate one per run; bifurcation one; regime map:
# regimes and contact loss; interval, Monte Carlo, PCE one each; Sobol: bars and lines per QoI
EXPECTED_FIGURES = {"panels": 1, "bifurcation": 1, "regime_map": 2, "envelope": 1, "monte_carlo": 1, "pbox": 1,
                    "pce": 1, "sobol": 6, "continuation": 2, "prediction": 1, "rating": 1, "runup": 2}


def test_every_figure_is_an_embedded_png(parsed):
    figures = {s["id"][len("analysis-"):]: len(s["images"]) for s in parsed.sections
               if s["id"].startswith("analysis-")}
    assert figures == EXPECTED_FIGURES
    assert len(parsed.images) == sum(EXPECTED_FIGURES.values())
    for source in parsed.images:
        prefix = "data:image/png;base64,"
        assert source.startswith(prefix)
        data = base64.b64decode(source[len(prefix):], validate=True)
        assert data[:8] == PNG_SIGNATURE and len(data) > 5000


def test_report_is_self_contained(parsed, smoke_report):
    assert parsed.external == []
    assert not parsed.tags & {"script", "link", "iframe", "object", "embed"}
    text = smoke_report[1]
    assert "http://" not in text.replace("http://www.w3.org", "") and "https://" not in text


def test_summary_holds_design_parameters_seed_and_versions(parsed, smoke_report):
    cells = parsed.cells
    study = load_study(STUDIES / "smoke.yaml")
    assert "20240601" in cells  # the seed
    assert "21 teeth" in cells and "101 teeth" in cells
    assert "0.06" in cells  # the zeta_mesh override, in the design table
    t2 = study.uncertain["adhesion_torque"]
    assert any(cell.startswith(f"interval [{t2.lower / 1e3:.4g} kN m, {t2.upper / 1e3:.4g} kN m]") for cell in cells)
    for package in ("numpy", "scipy", "xarray", "chaospy", "SALib", "numba", "uqgear", "python"):
        assert package in cells
    assert any(cell.endswith("s (sum over analyses)") for cell in cells)


def test_caveats_state_assumptions(smoke_report):
    text = smoke_report[1]
    caveats = text[text.index('id="caveats"'):text.index('class="analysis"')]
    assert "treated as uniform on their intervals" in caveats  # Sobol
    assert "Monte Carlo: interval parameters uniform on the interval bounds" in caveats
    assert "regimes classified from 32 Poincaré points" in caveats
    assert "pbox: p-box from a scan of 3 points per interval parameter with 4 random samples" in caveats


def test_findings_are_computed_from_the_data(smoke_report):
    folder, text = smoke_report
    findings = text[text.index('id="findings"'):text.index('id="caveats"')]
    envelope = load_results(folder)[3]
    assert envelope.attrs["analysis_name"] == "envelope"
    upper = envelope["dte_rms"].sel(bound="upper").values
    peak = int(np.argmax(upper))
    speed = envelope["pinion_speed"].values[peak]
    assert f"RMS DTE: highest upper bound {upper[peak] * 1e6:.4g} µm at {speed:.4g} rpm" in findings
    panels = load_results(folder)[0]
    assert f"speed = 4000 rpm, T1 = 1 kN m, T2 = 33.83 kN m: {panels['regime'].values[0]}" in findings


def test_regime_findings_describe_where_a_regime_occurs():
    speeds = np.arange(1750.0, 2076.0, 10.0)
    torques = np.array([30e3, 34e3, 38e3, 42e3, 46e3])
    labels = np.full((speeds.size, torques.size), "period-1", dtype=object)
    chaotic = (speeds >= 1830) & (speeds <= 1990)
    labels[np.ix_(chaotic, torques >= 38e3)] = "chaotic"
    labels[speeds > 2040, 0] = "period-2"
    labels[speeds > 2060, 0] = "period-4"
    regime = xr.DataArray(labels.astype(str), dims=("pinion_speed", "adhesion_torque"),
                          coords={"pinion_speed": speeds, "adhesion_torque": torques})
    sentences = regime_findings(regime, "pinion_speed", "adhesion_torque")
    assert sentences == ["period-n (n = 2, 4) between 2050 and 2070 rpm at T2 = 30 kN m",
                         "chaotic between 1830 and 1990 rpm when T2 >= 38 kN m"]
    plain = regime_findings(xr.full_like(regime.isel(adhesion_torque=0), "period-1"), "pinion_speed")
    assert plain == ["period-1 (harmonic) response everywhere on speed in [1750 rpm, 2070 rpm]"]


def test_unknown_analysis_type_gets_a_generic_section(smoke_report, tmp_path):
    folder = smoke_report[0]
    results = load_results(folder)[:1]
    future = xr.Dataset({"posterior": ("draw", np.arange(5.0), {"units": "N m"})},
                        attrs={**results[0].attrs, "analysis_type": "design_optimisation", "analysis_name": "fit",
                               "analysis_index": 1})
    text = build_report([results[0], future], dpi=50)
    assert 'id="analysis-fit" data-type="design_optimisation"' in text and "posterior" in text


def test_load_results_rejects_foreign_files(tmp_path):
    with pytest.raises(UqgearError, match="no result files"):
        load_results(tmp_path)
    save_result(xr.Dataset({"x": ("t", [1.0, 2.0])}), tmp_path / "other.nc")
    with pytest.raises(UqgearError, match="not an analysis result"):
        load_results(tmp_path)
    with pytest.raises(UqgearError, match="no such folder"):
        write_report(tmp_path / "absent")
    assert not (tmp_path / REPORT_NAME).exists()


def test_axis_labels_carry_units():
    for name in VARIABLES:
        label = axis_label(name)
        assert label.endswith("]") and "[" in label, label
    assert axis_label("adhesion_torque") == "adhesion torque $T_2$ [kN m]"
    assert axis_label("dte_rms") == "RMS DTE [µm]"


def test_report_records_provenance_of_the_study_text(smoke_report):
    folder, text = smoke_report
    study_text = (STUDIES / "smoke.yaml").read_text()
    assert json.dumps(study_text)[1:40] in json.dumps(load_results(folder)[0].attrs["study"])
    assert "Study definition" in text and "adhesion_coefficient: [0.15, 0.33]" in text


def test_figures_drawn_in_forked_processes_are_the_bytes_drawn_here():
    """figure_pngs draws each figure whole in one process: the PNGs are those of drawing them in order here."""
    from uqgear.report.page import figure_pngs, new_figure

    def maker(frequency):
        def make():
            figure = new_figure(3.0, 2.0, layout=None)
            axis = figure.subplots()
            t = np.linspace(0.0, 1.0, 500)
            axis.semilogy(t, 1.5 + np.sin(2 * np.pi * frequency * t))
            axis.set_title(f"{frequency} Hz")
            return figure
        return make

    makers = [maker(f) for f in (1.0, 3.0, 7.0)]
    here = figure_pngs(makers, 60, tight=True, processes=1)
    forked = figure_pngs(makers, 60, tight=True, processes=2)
    assert all(png.startswith(PNG_SIGNATURE) for png in here)
    assert forked == here
    assert len(set(here)) == 3


def test_the_report_says_which_eccentricities_a_stiffness_modulation_let_be_named_on_gears_with_pitch_errors():
    from uqgear.report.diagnosis_report import _pitch_error_notes

    applied = {"applied": True, "reason": "sidebands at every order on both shafts", "draws": 12}
    ranking = [{"variant": "eccentricity[pinion]", "modulation_gain": 34.04},
               {"variant": "friction"}]
    notes = _pitch_error_notes({"pitch_errors": applied, "ranking": ranking})
    assert len(notes) == 2 and "12 random draws" in notes[0]
    assert "eccentricity[pinion] 34.0 nats" in notes[1] and "friction" not in notes[1]
    # nothing measured: the allowance alone; no allowance: one note; none at all: nothing
    assert len(_pitch_error_notes({"pitch_errors": applied, "ranking": ranking[1:]})) == 1
    skipped = _pitch_error_notes({"pitch_errors": {"applied": False, "reason": "perfect gears"}, "ranking": []})
    assert skipped == ['<p class="note">Pitch errors: no allowance (perfect gears).</p>']
    assert _pitch_error_notes({"pitch_errors": None}) == []


def test_the_report_gives_each_shafts_sideband_phase_evidence_and_whether_it_named_an_eccentricity():
    from uqgear.report.diagnosis_report import _pitch_error_notes

    applied = {"applied": True, "reason": "sidebands at every order on both shafts", "draws": 12}
    phases = [{"shaft": "pinion", "run_out_m": 19.3e-6, "kappa": 0.01, "log_ratio": 684.6,
               "log_ratio_all_runs": 1403.5, "n_sums": 72, "threshold": 200.0, "named": True}]
    notes = _pitch_error_notes({"pitch_errors": applied, "ranking": [], "sideband_phases": phases})
    assert len(notes) == 2 and "200 nats" in notes[1]
    assert "pinion 685 nats over 72 sums (kappa 0.01, named)" in notes[1]
    quiet = [{**phases[0], "log_ratio": -12.0, "named": False}]
    notes = _pitch_error_notes({"pitch_errors": applied, "ranking": [], "sideband_phases": quiet})
    assert "pinion -12 nats over 72 sums (kappa 0.01, not named)" in notes[1]
    assert len(_pitch_error_notes({"pitch_errors": applied, "ranking": [], "sideband_phases": []})) == 1


def test_the_report_shows_each_gear_orders_factor_on_the_pitch_error_allowance_with_its_range():
    from uqgear.report.diagnosis_report import _pitch_error_notes

    applied = {"applied": True, "reason": "sidebands at every order on both shafts", "draws": 12,
               "order_factors": {"gear": {"2": {"factor": 0.0805, "low": 0.0108, "high": 6.49, "amplitude_m": 2.1e-6,
                                                "amplitude_range_m": [0.8e-6, 19.0e-6]}},
                                 "pinion": {"1": {"factor": 3.32, "low": 0.00545, "high": 4.43,
                                                  "amplitude_m": 27.9e-6, "amplitude_range_m": [1.1e-6, 31.2e-6],
                                                  "share_of_class_gears_below": 0.957}}}}
    notes = _pitch_error_notes({"pitch_errors": applied, "ranking": []})
    assert len(notes) == 3 and "one draw, the same in every run" in notes[1]
    table = notes[2]
    assert table.count("<tr>") == 3 and "0.0108 to 6.49" in table and "0.00545 to 4.43" in table
    assert ">pinion<" in table and ">gear<" in table and "1.1 to 31.2" in table and "run-out" in notes[1]
    # the share of class gears below what was read (absent in older summaries: a dash)
    assert "class gears below" in table and ">96 %<" in table and ">-<" in table


def test_a_run_out_that_cannot_be_told_from_pitch_errors_is_a_headline_finding():
    from uqgear.report.diagnosis_report import diagnosis_findings

    reason = ("the pinion's first-order lines read as a run-out of 20 um along the line of action, more than 92 % "
              "of ISO 1328-1 class 6 to 8 pinions have from their pitch errors: ...")
    content = {"verdict": "friction", "reason": "friction named", "effects": [], "gap": {}, "where": [],
               "rig": {"n_op": 8}, "borderline": [],
               "cannot_tell": [{"effect": "eccentricity", "shaft": "pinion", "run_out_m": 20e-6,
                                "share_of_class_gears_below": 0.92, "classes": [6, 8], "reason": reason}]}
    findings = [f for f in diagnosis_findings(content) if f.topic == "cannot_tell"]
    assert len(findings) == 1 and findings[0].text == f"Cannot tell: {reason}."
    assert findings[0].facts["shaft"] == "pinion" and findings[0].facts["run_out_m"] == 20e-6
    assert not [f for f in diagnosis_findings({**content, "cannot_tell": []}) if f.topic == "cannot_tell"]
