"""credcli: can you trust the covariance your estimator reports, and if not, why not?

The method is Yan, Hsu and Sun, "Credible Uncertainty Quantification under Noise and
System Model Mismatch": NEES/NCI, Gaussian NLL and energy score, an energy-distance
location test and directional probes (Algorithm 1).
"""

from credcli.engine.diagnosis import (
    Diagnosis,
    DiagnosisConfig,
    Label,
    MetricsLevel,
    SegmentDiagnosis,
    SrdForm,
    Variant,
    diagnose,
    diagnose_errors,
    diagnose_log,
    diagnose_variants,
    nci_baseline,
    nees_baseline,
)
from credcli.engine.elt import ELTResult, location_test
from credcli.engine.metrics import (
    anees,
    energy_score,
    expected_norm,
    gaussian_nll,
    mse_matrix,
    nci,
    nees,
    probes,
    srd,
)
from credcli.engine.scale import ScaleTest
from credcli.errors import CredcliError
from credcli.io.logs import CovKind, EstimatorLog, LogSchema, load_log

__version__ = "0.1.0"

__all__ = [
    "CovKind",
    "CredcliError",
    "Diagnosis",
    "DiagnosisConfig",
    "ELTResult",
    "EstimatorLog",
    "Label",
    "LogSchema",
    "MetricsLevel",
    "ScaleTest",
    "SegmentDiagnosis",
    "SrdForm",
    "Variant",
    "__version__",
    "anees",
    "diagnose",
    "diagnose_errors",
    "diagnose_log",
    "diagnose_variants",
    "energy_score",
    "expected_norm",
    "gaussian_nll",
    "load_log",
    "location_test",
    "mse_matrix",
    "nci",
    "nci_baseline",
    "nees",
    "nees_baseline",
    "probes",
    "srd",
]
