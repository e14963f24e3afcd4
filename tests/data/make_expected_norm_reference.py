"""Writes expected_norm_reference.json: E‖W‖ for W ~ N(m, S) at 30 digits (mpmath).

E‖W‖ = (1/(2√π)) ∫_0^∞ (1 − E e^{−tQ}) t^{−3/2} dt, Q = ‖W‖², with
E e^{−tQ} = Π_i (1 + 2tλ_i)^{−1/2} exp(−t Σ_i ν_i²/(1 + 2tλ_i)) (λ the eigenvalues of S,
ν = Uᵀm), integrated by mpmath's tanh-sinh quadrature in u = log t over intervals split
at the scales of the problem. Run: python tests/data/make_expected_norm_reference.py
(needs mpmath; the JSON is committed, so the tests do not).
"""

import json
from pathlib import Path

import numpy as np


def reference(lam, nu2) -> str:
    import mpmath as mp  # only to regenerate the reference, not a test dependency

    mp.mp.dps = 30
    lam = [mp.mpf(float(x)) for x in lam]
    nu2 = [mp.mpf(float(x)) for x in nu2]

    def integrand(u):
        t = mp.e**u
        log_phi = mp.mpf(0)
        for la, n2 in zip(lam, nu2):
            log_phi += -mp.log1p(2 * t * la) / 2 - t * n2 / (1 + 2 * t * la)
        return -mp.expm1(log_phi) * mp.e ** (-u / 2)

    scales = sorted({float(mp.log(1 / (2 * la))) for la in lam if la > 0})
    points = [-mp.inf, -60] + [mp.mpf(s) for s in scales] + [60, mp.inf]
    points = sorted(set(points), key=lambda x: float(x))
    value = mp.quad(integrand, points) / (2 * mp.sqrt(mp.pi))
    return mp.nstr(value, 28)


def main() -> None:
    rng = np.random.default_rng(2026)
    cases = []
    for d in (1, 2, 3, 6):
        for _ in range(12):
            lam = rng.uniform(0, 1, d) * 10.0 ** rng.uniform(-11, 3, d)
            nu2 = (rng.standard_normal(d) * 10.0 ** rng.uniform(-6, 3)) ** 2
            if rng.uniform() < 0.25:
                nu2[:] = 0.0
            cases.append(
                {"lam": lam.tolist(), "nu2": nu2.tolist(), "expected_norm": reference(lam, nu2)}
            )
    out = Path(__file__).with_name("expected_norm_reference.json")
    out.write_text(json.dumps(cases, indent=1) + "\n")


if __name__ == "__main__":
    main()
