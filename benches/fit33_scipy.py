"""Times SciPy's least_squares on the fit of Eq. (33), for benches/fit33_vs_scipy.sh.

usage: python fit33_scipy.py DATA.txt ALPHA0 SIGMA0 WA0 [REPEATS]

DATA.txt: dt on the first line, one normalised current sample per line after it (the same
file the Rust side reads). SciPy gets the analytic Jacobian, so that both sides do the same
mathematics; for each method ('trf', 'lm') it prints the median wall time of the whole
least_squares call and the fitted parameters.
"""
import sys
import time

import numpy as np
from scipy.optimize import least_squares


def model(p, t):
    alpha, sigma, wa = p
    return 1.0 + alpha * np.exp(-sigma * t) * np.sinh(wa * t - np.arcsinh(1.0 / alpha))


def residuals(p, t, y):
    return model(p, t) - y


def jacobian(p, t, y):
    alpha, sigma, wa = p
    u = wa * t - np.arcsinh(1.0 / alpha)
    e = np.exp(-sigma * t)
    s, c = e * np.sinh(u), e * np.cosh(u)
    return np.column_stack((s + c / np.sqrt(alpha * alpha + 1.0), -t * alpha * s, t * alpha * c))


def main():
    path, a0, s0, w0 = sys.argv[1], *map(float, sys.argv[2:5])
    repeats = int(sys.argv[5]) if len(sys.argv) > 5 else 20
    with open(path) as f:
        dt = float(f.readline())
        y = np.array([float(line) for line in f if line.strip()])
    t = dt * np.arange(len(y))
    for method in ("trf", "lm"):
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            fit = least_squares(residuals, [a0, s0, w0], jac=jacobian, args=(t, y), method=method)
            times.append(time.perf_counter() - start)
        times.sort()
        a, s, w = fit.x
        print(f"scipy_{method}_median_s {times[len(times) // 2]:.6e} alpha {a:.9f} sigma {s:.9f} wa {w:.9f} nfev {fit.nfev} status {fit.status}")


if __name__ == "__main__":
    main()
