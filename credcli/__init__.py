"""credcli: can you trust the covariance your estimator reports, and if not, why not?

The method starts from Yan, Hsu and Sun, "Credible Uncertainty Quantification under Noise
and System Model Mismatch": NEES/NCI, Gaussian NLL and energy score, an energy-distance
location test and directional probes (Algorithm 1), and adds a calibrated, dependence-aware
decision rule (the default).

The Python API, in one path (see docs/python.md)::

    log = credcli.read_log("log.csv")
    results = credcli.diagnose_log(log)          # or segments="5s", "whole", [...]
    results.to_frame(); results.to_dict()
    credcli.diagnose(errors, cov)                # arrays, one segment
    log = credcli.log_from_arrays(truth, estimate, cov, time=..., segment=...)
    log = credcli.log_from_arrays(errors=e, cov=cov)  # cov (N, d, d), (d, d) or (N, d)
    log = credcli.log_from_frame(df)             # or errors=[...], cov=[...], time="t"
    credcli.write_log(log, "log.parquet")        # for credcli diagnose / gate
    credcli.diagnose_monte_carlo([run_1, run_2, ...])

Names are imported on first use, so ``import credcli`` (and ``credcli --help``) stays fast.
"""

from __future__ import annotations

import importlib

from credcli.version import __version__  # noqa: F401 (the package's __version__)

_EXPORTS = {
    "read_log": "credcli.api",
    "diagnose_log": "credcli.api",
    "diagnose": "credcli.api",
    "Results": "credcli.api",
    "MonteCarloResults": "credcli.api",
    "log_from_arrays": "credcli.api",
    "log_from_frame": "credcli.api",
    "write_log": "credcli.api",
    "diagnose_monte_carlo": "credcli.api",
    "Diagnosis": "credcli.engine.diagnosis",
    "DiagnosisConfig": "credcli.engine.diagnosis",
    "Label": "credcli.engine.diagnosis",
    "MetricsLevel": "credcli.engine.diagnosis",
    "SegmentDiagnosis": "credcli.engine.diagnosis",
    "SrdForm": "credcli.engine.diagnosis",
    "Variant": "credcli.engine.diagnosis",
    "diagnose_variants": "credcli.engine.diagnosis",
    "nci_baseline": "credcli.engine.diagnosis",
    "nees_baseline": "credcli.engine.diagnosis",
    "ELTResult": "credcli.engine.elt",
    "location_test": "credcli.engine.elt",
    "ScaleTest": "credcli.engine.scale",
    "anees": "credcli.engine.metrics",
    "energy_score": "credcli.engine.metrics",
    "expected_norm": "credcli.engine.metrics",
    "gaussian_nll": "credcli.engine.metrics",
    "mse_matrix": "credcli.engine.metrics",
    "nci": "credcli.engine.metrics",
    "nees": "credcli.engine.metrics",
    "probes": "credcli.engine.metrics",
    "srd": "credcli.engine.metrics",
    "CredcliError": "credcli.errors",
    "CovKind": "credcli.io.logs",
    "EstimatorLog": "credcli.io.logs",
    "LogSchema": "credcli.io.logs",
}

__all__ = sorted([*_EXPORTS, "__version__"])


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'credcli' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
