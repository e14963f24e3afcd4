"""`credcli simulate`: scenarios, fidelity to Tables II and III, sweeps, Fig. 1, determinism."""

from __future__ import annotations

import json
import math
import sys

import numpy as np
import pytest

from credcli.cli import main
from credcli.engine import metrics
from credcli.engine.diagnosis import DIAGNOSIS_LABELS, Label
from credcli.errors import CredcliError
from credcli.report.builders import PAPER_TABLE_II
from credcli.studies import simulate as sim


def _run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_scenario_names_and_aliases():
    assert sim.parse_scenarios("pess+smm") == [Label.PESSIMISM_SMM]
    assert sim.parse_scenarios("cred,opt,pess,opt+smm,smm") == [
        Label.CREDIBLE,
        Label.OPTIMISM,
        Label.PESSIMISM,
        Label.OPTIMISM_SMM,
        Label.SMM,
    ]
    assert sim.parse_scenarios("all") == list(DIAGNOSIS_LABELS)
    with pytest.raises(CredcliError, match="unknown scenario 'bogus'"):
        sim.parse_scenarios("bogus")


def test_draw_trial_follows_section_iv_a():
    config = sim.SimulationConfig()
    spec = config.spec(Label.OPTIMISM_SMM)
    rhos, norms = [], []
    for t in range(200):
        gen = np.random.default_rng(t)
        errors, cov = sim.draw_trial(spec, 4000, 2, (0.5, 2.0), gen)
        gen = np.random.default_rng(t)  # replay the draws: Q, λ, ρ, direction, ‖μ‖
        q, _ = np.linalg.qr(gen.standard_normal((2, 2)))
        lam = gen.uniform(0.5, 2.0, 2)
        sigma = (q * lam) @ q.T
        rho = gen.uniform(0.1, 0.8)
        direction = gen.standard_normal(2)
        mu = direction / np.linalg.norm(direction) * gen.uniform(1.6, 2.4)
        np.testing.assert_allclose(cov[0], rho * sigma)
        if t < 5:  # e ~ N(−μ, Σ)
            assert np.abs(errors.mean(0) + mu).max() < 5 * np.sqrt(lam.max() / 4000)
            np.testing.assert_allclose(np.cov(errors.T), sigma, atol=0.15)
        rhos.append(rho)
        norms.append(np.linalg.norm(mu))
    assert 0.1 <= min(rhos) and max(rhos) <= 0.8 and 1.6 <= min(norms) and max(norms) <= 2.4


def test_truth_label_from_parameters():
    assert sim.ScenarioSpec((1, 1), (0, 0)).truth is Label.CREDIBLE
    assert sim.ScenarioSpec((0.5, 0.5), (1, 2)).truth is Label.OPTIMISM_SMM
    assert sim.ScenarioSpec((2, 3), (0, 0)).truth is Label.PESSIMISM
    with pytest.raises(CredcliError, match="straddle"):
        _ = sim.ScenarioSpec((0.5, 2), (0, 0)).truth


def _check_default_protocol(study) -> None:
    """The authors' variant (ks) at seed 0 is within ±8 points of Table II, with exactly the
    figures of credcli 0.1 (96/76/82/80/90/100: its sign flips are drawn as before)."""
    for label in DIAGNOSIS_LABELS:
        ours = study.accuracy[sim.Method.KS][label]
        assert abs(ours - PAPER_TABLE_II[label.value]) <= 0.08 + 1e-9, label
    ks = [study.accuracy[sim.Method.KS][lab] for lab in DIAGNOSIS_LABELS]
    assert ks == [0.96, 0.76, 0.82, 0.80, 0.90, 1.00]
    # Table III: 50 per row; pessimism+smm is always found, as in the paper
    for label in DIAGNOSIS_LABELS:
        assert sum(study.confusion[label].values()) == 50
    assert study.confusion[Label.PESSIMISM_SMM][Label.PESSIMISM_SMM] >= 49


@pytest.mark.slow
def test_default_protocol_and_mean_over_seeds_are_close_to_table_ii():
    """Seed 0 is the default protocol (:func:`_check_default_protocol`, its study made once
    for both checks). Averaged over 4 seeds (200 trials per scenario, s.e. ~2.8 points) the
    ks variant is within 8 points of the paper in every scenario, and the calibrated
    variant is at least 85 % in every scenario (its 20-seed figures are 90.1–98.3 %,
    docs/measured.md) and beats ks on average."""
    ks, cal = [], []
    for seed in range(4):
        study = sim.run_study(sim.SimulationConfig(seed=seed), list(DIAGNOSIS_LABELS))
        if seed == 0:
            assert sim.SimulationConfig(seed=0) == sim.SimulationConfig()  # the default
            _check_default_protocol(study)
        ks.append([study.accuracy[sim.Method.KS][lab] for lab in DIAGNOSIS_LABELS])
        cal.append([study.accuracy[sim.Method.CALIBRATED][lab] for lab in DIAGNOSIS_LABELS])
    paper = np.array([PAPER_TABLE_II[lab.value] for lab in DIAGNOSIS_LABELS])
    assert np.all(np.abs(np.mean(ks, axis=0) - paper) <= 0.08)
    assert np.all(np.mean(cal, axis=0) >= 0.85)
    assert np.mean(cal) > np.mean(ks) + 0.03


def test_jobs_do_not_change_output(tmp_path, capsys, monkeypatch):
    from credcli.schedule import pool as parallel

    outs = []
    for jobs, method in ((1, None), (2, "fork"), (2, "spawn")):
        if method is not None:  # forked and spawned workers alike
            monkeypatch.setattr(parallel, "start_method", lambda m=method: m)
        path = tmp_path / f"j{jobs}{method}.json"
        code, _, err = _run(
            capsys, "simulate", "--trials", "12", "--jobs", jobs, "-f", "json", "-o", path
        )
        assert code == 0, err
        outs.append(path.read_bytes())
    assert outs[0] == outs[1] == outs[2]


def test_workers_are_forked_only_from_a_single_thread_without_pyarrow(monkeypatch):
    import threading

    from credcli.schedule import pool as parallel

    if sys.platform != "linux":
        assert parallel.start_method() == "spawn"
        return
    import pyarrow  # noqa: F401

    monkeypatch.setattr(threading, "active_count", lambda: 1)
    assert parallel.start_method() == "spawn"  # Arrow's thread pools may be running
    monkeypatch.delitem(sys.modules, "pyarrow")
    assert parallel.start_method() == "fork"
    monkeypatch.setattr(threading, "active_count", lambda: 2)  # another thread runs
    assert parallel.start_method() == "spawn"


def test_json_structure_and_seed(capsys):
    _, out, err = _run(capsys, "simulate", "--trials", "10", "--seed", "4", "-f", "json")
    doc = json.loads(out)
    assert doc["parameters"]["seed"] == 4 and doc["parameters"]["trials"] == 10
    assert list(doc["accuracy"]) == ["calibrated", "ks", "paper", "nees", "nci"]
    assert list(doc["accuracy"]["calibrated"]) == [lab.value for lab in DIAGNOSIS_LABELS]
    assert doc["confusion_variant"] == "calibrated"
    for true, row in doc["confusion"].items():
        assert sum(row.values()) == 10
        assert doc["accuracy"]["calibrated"][true] == pytest.approx(row[true] / 10)
    assert "calibrated variant" in err  # summary line on stderr
    _, out2, _ = _run(capsys, "simulate", "--trials", "10", "--seed", "4", "-f", "json")
    assert out == out2


def test_scenario_alias_on_the_command_line(capsys):
    code, out, _ = _run(capsys, "simulate", "--scenario", "pess+smm", "--trials", "5", "-f", "csv")
    assert code == 0
    import csv
    import io

    rows = list(csv.DictReader(io.StringIO(out)))  # one valid CSV, a `table` column
    table2 = [r for r in rows if r["table"] == "Table II: diagnosis accuracy"]
    assert len(table2) == 1 and table2[0]["scenario"] == "pessimism+smm"
    assert table2[0]["calibrated"] == "100.0"
    table3 = [r for r in rows if r["table"].startswith("Table III")]
    assert len(table3) == 1 and table3[0]["pessimism+smm"] == "5"


def test_baselines_never_say_smm():
    study = sim.run_study(sim.SimulationConfig(trials=10), [Label.SMM, Label.OPTIMISM_SMM])
    assert (
        study.accuracy[sim.Method.NEES][Label.SMM] == 0 == study.accuracy[sim.Method.NCI][Label.SMM]
    )


def test_sweep_parsing():
    s = sim.Sweep.parse("rho=0.1:10:20")
    assert s.parameter is sim.SweepParameter.RHO and len(s.values) == 20 and s.values[-1] == 10
    assert sim.Sweep.parse("n=25,50,100").values == (25.0, 50.0, 100.0)
    assert sim.Sweep.parse("B=100,200").parameter is sim.SweepParameter.B
    for bad, msg in [
        ("rho", "expected NAME"),
        ("foo=1", "unknown parameter"),
        ("n=2.5", "positive integers"),
        ("rho=0,1", "> 0"),
        ("tau=a", "with numbers"),
    ]:
        with pytest.raises(CredcliError, match=msg):
            sim.Sweep.parse(bad)


def test_rho_sweep_derives_truth_from_rho(capsys):
    code, out, _ = _run(capsys, "simulate", "--sweep", "rho=0.5,1,4", "--trials", "6", "-f", "json")
    assert code == 0
    points = json.loads(out)["sweep"]["points"]
    truths = [(p["value"], p["scenario"]) for p in points]
    assert truths == [
        (0.5, "optimism"),
        (0.5, "optimism+smm"),
        (1.0, "credible"),
        (1.0, "smm"),
        (4.0, "pessimism"),
        (4.0, "pessimism+smm"),
    ]


def test_parameter_sweep_changes_the_setting(capsys):
    _, out, _ = _run(
        capsys,
        "simulate",
        "--sweep",
        "n=20,200",
        "--scenario",
        "smm",
        "--trials",
        "30",
        "-f",
        "json",
    )
    acc = [p["accuracy"]["ks"] for p in json.loads(out)["sweep"]["points"]]
    assert acc[1] > acc[0]  # more epochs, more power to see the bias


def test_fig1_curves_exact_and_monte_carlo_agree():
    rhos = [0.25, 0.5, 1.0, 2.0, 4.0]
    by_rho, by_gamma = sim.fig1_curves(rhos, [0.0, 1.0, 2.0], runs=4000)
    for p in by_rho + by_gamma:
        assert abs(p.mean_es - p.expected_es) < 0.05 * p.expected_es
        assert abs(p.mean_nll - p.expected_nll) < 0.05 * p.expected_nll
    es = {p.rho: p.expected_es for p in by_rho}
    nll = {p.rho: p.expected_nll for p in by_rho}
    assert es[4.0] > es[0.25] and es[2.0] > es[0.5]  # ES penalises pessimism more (Fig. 1a)
    assert nll[0.25] > nll[4.0]  # NLL penalises optimism more (Appendix B)
    assert min(es, key=es.get) == 1.0
    gam = [p.expected_es for p in by_gamma]
    assert gam[0] < gam[1] < gam[2]  # ES grows with bias (Fig. 1b)
    # ρ = 1, γ = 0: E[ES] = E‖N(0, 2I)‖ − ½E‖N(0, 2I)‖ = ½·√2·√(π/2) for d = 2
    assert es[1.0] == pytest.approx(0.5 * np.sqrt(2) * np.sqrt(np.pi / 2), rel=1e-9)
    ref = metrics.expected_norm(np.zeros((1, 2)), 2 * np.eye(2)[None])[0] / 2
    assert es[1.0] == pytest.approx(ref, rel=1e-12)


def test_bad_simulation_options(capsys):
    for args, msg in [
        (["--trials", "0"], "trials must be 1 … 1,000,000"),
        (["--rho-optimism", "0.5:1.5"], "optimism ρ range"),
        (["--bias", "2:1"], "lower end"),
        (["--rho-pessimism", "2:inf"], "must be finite numbers"),  # was exit 3 (numpy)
        (["--jobs", "0"], "--jobs"),
        (["--sweep", "x=1"], "unknown parameter"),
    ]:
        code, _, err = _run(capsys, "simulate", *args)
        assert code == 2 and msg in err and err.count("\n") == 1


@pytest.mark.parametrize("name", ["rho_pessimism", "bias", "eigenvalues"])
def test_a_study_range_must_be_finite(name):
    """An infinite upper end was accepted and failed in numpy's uniform draw (exit 3)."""
    from credcli.errors import CredcliError

    with pytest.raises(CredcliError, match="finite") as info:
        sim.SimulationConfig(**{name: (2.0, math.inf)})
    assert info.value.parameter == name


def test_curves_csv_cells_are_plain_numbers(tmp_path, capsys):
    """numpy floats reached the CSV as "np.float64(0.1)" (their repr) in the ρ column."""
    import csv

    out = tmp_path / "c.csv"
    assert main(["simulate", "--curves", "--curve-runs", "5", "-f", "csv", "-o", str(out)]) == 0
    with out.open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert rows and all(float(r["rho"]) > 0 and float(r["gamma"]) >= 0 for r in rows)


def test_the_study_reads_an_offset_by_what_it_draws():
    """Independent draws (the paper's protocol) hold no memory slower than a trial, so
    with ``slow_errors`` auto an offset the claim covers is pess+smm there; AR(1) draws may
    hold such memory; a choice that was given stays. Judged as a log's errors (possible),
    the paper's pess+smm trials lose exactly those whose offset the claim covers, to
    insufficient-data: every other count of the confusion row is the same."""
    from dataclasses import replace

    from credcli.engine.config import DiagnosisConfig, SlowErrors
    from credcli.studies.settings import SimulationConfig

    assert SimulationConfig().judged_by.slow_errors is SlowErrors.EXCLUDED
    assert SimulationConfig(ar=0.5).judged_by.slow_errors is SlowErrors.POSSIBLE
    for choice in SlowErrors:
        if choice is not SlowErrors.AUTO:
            given = SimulationConfig(diagnosis=DiagnosisConfig(slow_errors=choice.value))
            assert given.judged_by.slow_errors is choice

    truth = Label.PESSIMISM_SMM
    study = SimulationConfig(trials=40, seed=2)
    known = sim.run_study(study, [truth]).confusion[truth]
    as_log = sim.run_study(replace(study, diagnosis=given.diagnosis), [truth]).confusion[truth]
    declined = as_log[Label.INSUFFICIENT] - known[Label.INSUFFICIENT]
    assert declined > 0
    assert known[truth] - as_log[truth] == declined
    others = [lab for lab in known if lab not in (truth, Label.INSUFFICIENT)]
    assert [known[lab] for lab in others] == [as_log[lab] for lab in others]


@pytest.mark.parametrize(
    ("args", "shown"),
    [
        ([], "excluded"),
        (["--ar", "0.5"], "possible"),
        (["--slow-errors", "possible"], "possible"),
        (["--sweep", "ar=0,0.5"], "auto"),
    ],
)
def test_the_json_names_the_slow_errors_the_trials_were_judged_by(args, shown, capsys):
    """`simulate`'s parameters say how its trials read an offset: `auto` resolved from
    ``ar`` (independent draws: excluded; AR(1): possible), a given choice as given, and
    `auto` only where a sweep of ``ar`` resolves it at each point."""
    code = main(["simulate", "--trials", "2", "--scenario", "credible", "-f", "json", *args])
    assert code == 0
    assert json.loads(capsys.readouterr().out)["parameters"]["slow_errors"] == shown


@pytest.mark.parametrize("nu", ["2.0001", "3", "4", "inf"])
def test_student_t_noise_needs_a_finite_fourth_moment(nu, capsys):
    """The scale test's variance is the NEES's, finite only for ν > 4: at ν = 2.0001 a
    credible claim was labelled pessimism in 99 of 100 trials."""
    assert main(["simulate", "--noise", f"student-t:{nu}", "--trials", "2"]) == 2
    err = capsys.readouterr().err
    assert "must be a finite number > 4" in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--sweep", "rho=1,2", "--sweep", "n=20,30"], "--sweep is given 2 times"),
        (["--sweep", "rho=1,2", "--curves"], "--sweep and --curves make different tables"),
    ],
)
def test_a_sweep_asked_twice_or_beside_the_curves_is_refused(args, message, capsys):
    """The first of two sweeps, or a sweep beside the curves, was dropped silently."""
    assert main(["simulate", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
