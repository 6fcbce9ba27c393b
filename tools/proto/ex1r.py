"""Issue 15, Example 1 of Zhao 2019: can an honest data-driven rule reach the S bars?

Dense numpy prototype (uses fs.py beside it; /usr/bin/python3 with numpy/scipy).  Every rule is a
Gaussian prior on the unknowns with its hyperparameters chosen by REML (sigma held at the sigma-hat
of the redundant equations unless said otherwise); S, gamma and their posterior u come from the
same dense posterior.  Noise: independent on each sensor reading (section 3 of the paper).

  python3 ex1r.py ex1  RULES [batches]        # Example 1: median over batches of 20 runs
  python3 ex1r.py cov  RULES N1,N2 s1,s2 seeds  # random multi-harmonic profiles: coverage of u_S

RULES (comma separated):
  LS     no prior (exact least squares covariance)
  D2f    second difference on f, REML, sigma fixed (errsep's default)
  D2e    the same with sigma estimated (profiled) by REML
  D1f D3f  first / third difference on f
  EVf    the order (D1/D2/D3) chosen per data set by the REML evidence
  ALf    fractional order: spectrum 1/kappa^alpha on f, alpha and scale by REML (alpha 0 = identity)
  If     identity on f (the prototype that reached the bars; not a rule the evidence picks)
  MIXf   precision a*I + b*D2'D2 on f, two scales by REML
  SHOf   damped-oscillator spectrum on f (peak kappa0, width, scale by REML)
  FLf    the default's long-wave spectrum (T^2, its own REML scale) kept as a floor, an SHO peak
         added on top by REML (prior covariance never below the floor)
  EVSf   D2f or SHOf, whichever has the smaller REML -2 log L + 2 per hyperparameter (AIC)
  EVSHf  the same without the charge
  SHD2f  covariance sum of a D2-like tail (1/kappa^2) and the SHO peak, four scales by REML
  PMf    D2 prior, posterior averaged over lambda with REML weights instead of the REML lambda
  SD2f   D2 on f and D2 on S, two lambdas jointly by REML (full model with S, gamma unknown)
  SGD2f  D2 on f, S and gamma, three lambdas by REML
"""
import sys
import time

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.optimize import minimize, minimize_scalar

sys.path.insert(0, __file__.rsplit('/', 1)[0])
from fs import Model, add_D3, example1, simulate, truth_random, geometry  # noqa: E402


def dmat(n, order):
    c = {1: [-1, 1], 2: [1, -2, 1], 3: [-1, 3, -3, 1]}[order]
    D = np.zeros((n - order, n))
    for i in range(n - order):
        D[i, i:i + order + 1] = c
    return D


class Rules:
    """Priors on the projected model of fs.Model (unknowns f(1..N-2), eta1, eta2)."""

    def __init__(self, N):
        self.mod = Model(N)
        add_D3(self.mod)
        mod = self.mod
        n = mod.n_f
        # sine basis of the Dirichlet Laplacian on f(1..N-2): kappa ~ omega^2
        i = np.arange(1, n + 1)
        self.V = np.sqrt(2.0 / (n + 1)) * np.sin(np.outer(i, i) * np.pi / (n + 1))
        self.kap = 2 - 2 * np.cos(i * np.pi / (n + 1))
        self.Pf = {k: mod.pens[k][:n, :n] for k in ('I', 'D1', 'D2', 'D3')}
        self.ldP = {k: np.linalg.slogdet(v)[1] for k, v in self.Pf.items()}
        self.T = mod.gauge_T()
        self.G_S, self.G_g = mod.lin_SG()
        self._full = None

    # ---- projected model: prior precision Pi_f (in sigma^2 units) on f -----------------------
    def crit(self, y, Aty, Pi_f, ldPi_f, s):
        mod = self.mod
        M = mod.AtA.copy()
        M[:mod.n_f, :mod.n_f] += Pi_f
        try:
            cf = cho_factor(M)
        except np.linalg.LinAlgError:
            return 1e30
        x = cho_solve(cf, Aty)
        r = y - mod.A @ x
        q = r @ r + x[:mod.n_f] @ Pi_f @ x[:mod.n_f]
        return q / s**2 + 2 * np.sum(np.log(np.diag(cf[0]))) - ldPi_f

    def post(self, m, Pi_f, s):
        mod = self.mod
        M = mod.AtA.copy()
        M[:mod.n_f, :mod.n_f] += Pi_f
        cf = cho_factor(M)
        x = cho_solve(cf, mod.A.T @ mod.y(m))
        xG = self.T @ x
        Minv = cho_solve(cf, np.eye(mod.nx))
        Sig = s**2 * self.T @ Minv @ self.T.T
        S = m @ mod.W[0] - self.G_S @ xG
        g = m @ mod.W[1] - self.G_g @ xG
        vS = s**2 * (mod.W[0] @ mod.W[0]) + np.einsum('ij,jk,ik->i', self.G_S, Sig, self.G_S)
        vg = s**2 * (mod.W[1] @ mod.W[1]) + np.einsum('ij,jk,ik->i', self.G_g, Sig, self.G_g)
        return S, g, vS, vg

    def spectral(self, p):
        """precision (sigma^2 units, s=1) of a prior covariance V diag(p) V'."""
        return (self.V / p) @ self.V.T, -np.sum(np.log(p))

    def fit(self, rule, m, s_ls):
        mod = self.mod
        y = mod.y(m)
        Aty = mod.A.T @ y
        n = mod.n_f
        s = s_ls
        info = {}
        if rule == 'LS':
            return self.post(m, 1e-10 * np.eye(n), s) + (info,)
        if rule in ('D1f', 'D2f', 'D3f', 'If', 'D2e', 'EVf', 'PMf'):
            cands = {'EVf': ['D1', 'D2', 'D3'], 'PMf': ['D2'], 'D2e': ['D2']}.get(rule, [rule[:-1]])
            best = None
            for pen in cands:
                Pf, ld = self.Pf[pen], self.ldP[pen]
                if rule == 'D2e':
                    def c(ll):
                        lam2 = 10**(2 * ll)
                        Mx = mod.AtA.copy(); Mx[:n, :n] += lam2 * Pf
                        try:
                            cf = cho_factor(Mx)
                        except np.linalg.LinAlgError:
                            return 1e30
                        x = cho_solve(cf, Aty); r = y - mod.A @ x
                        q = r @ r + lam2 * x[:n] @ Pf @ x[:n]
                        return (len(y) - 2) * np.log(q) + 2 * np.sum(np.log(np.diag(cf[0]))) - n * np.log(lam2)
                else:
                    def c(ll):
                        return self.crit(y, Aty, 10**(2 * ll) * Pf, n * 2 * ll * np.log(10) + ld, s)
                grid = np.linspace(-4, 6, 41)
                v = np.array([c(g) for g in grid])
                if rule == 'PMf':
                    w = np.exp(-(v - v.min()) / 2)
                    w /= w.sum()
                    acc = None
                    for gi, wi in zip(grid, w):
                        if wi < 1e-6:
                            continue
                        S, g, vS, vg = self.post(m, 10**(2 * gi) * Pf, s)
                        if acc is None:
                            acc = [0 * S, 0 * g, 0 * vS, 0 * vg, 0 * S, 0 * g]
                        acc[0] += wi * S; acc[1] += wi * g; acc[2] += wi * vS; acc[3] += wi * vg
                        acc[4] += wi * S**2; acc[5] += wi * g**2
                    tot = w[w >= 1e-6].sum()
                    S, g = acc[0] / tot, acc[1] / tot
                    vS = acc[2] / tot + acc[4] / tot - S**2
                    vg = acc[3] / tot + acc[5] / tot - g**2
                    return S, g, vS, vg, info
                i = int(np.argmin(v))
                r = minimize_scalar(c, bounds=(grid[max(i - 1, 0)], grid[min(i + 1, 40)]), method='bounded',
                                    options=dict(xatol=0.01))
                if best is None or r.fun < best[0]:
                    best = (r.fun, pen, r.x)
            _, pen, ll = best
            info['pen'] = pen
            info['ll'] = ll
            info['crit'] = best[0]
            if rule == 'D2e':
                Mx = mod.AtA.copy(); Mx[:n, :n] += 10**(2 * ll) * self.Pf[pen]
                x = np.linalg.solve(Mx, Aty); r = y - mod.A @ x
                s = np.sqrt((r @ r + 10**(2 * ll) * x[:n] @ self.Pf[pen] @ x[:n]) / (len(y) - 2))
            return self.post(m, 10**(2 * ll) * self.Pf[pen], s) + (info,)
        if rule in ('ALf', 'MIXf', 'SHOf', 'SHD2f'):
            kap = self.kap
            if rule == 'ALf':
                def prec(th):   # th = (log10 scale^2, alpha)
                    return self.spectral(10**th[0] / kap**th[1])
                starts = [(a, b) for a in (-2, 0, 2) for b in (0.0, 1.0, 2.0, 3.0)]
            elif rule == 'MIXf':
                def prec(th):   # precision 10^a I + 10^b D2'D2
                    P = 10**th[0] * self.Pf['I'] + 10**th[1] * self.Pf['D2']
                    return P, np.linalg.slogdet(P)[1]
                starts = [(a, b) for a in (-2, 0, 2) for b in (-1, 1, 3)]
            elif rule == 'SHD2f':
                def prec(th):   # covariance sum: D2-like tail 10^a/kappa^2 + SHO peak
                    k0, h = 10**th[2], 10**th[3]
                    return self.spectral(10**th[0] / kap**2 + 10**th[1] / ((kap - k0)**2 + h * kap + 1e-12))
                starts = [(a0, a, b, c) for a0 in (-6, -3) for a in (-4, -2) for b in np.log10(kap[[1, 4, 12]])
                          for c in (-3, -1)]
            else:
                def prec(th):   # th = (log10 scale^2, log10 kappa0, log10 width)
                    k0, h = 10**th[1], 10**th[2]
                    return self.spectral(10**th[0] / ((kap - k0)**2 + h * kap + 1e-12))
                starts = [(a, b, c) for a in (-4, -2) for b in np.log10(kap[[1, 4, 12]]) for c in (-3, -1)]

            def cth(th):
                P, ld = prec(th)
                return self.crit(y, Aty, P, ld, s)
            best = min((cth(np.array(st, float)), st) for st in starts)
            r = minimize(cth, np.array(best[1], float), method='Nelder-Mead',
                         options=dict(xatol=0.02, fatol=1e-3, maxiter=300))
            info['th'] = r.x
            info['crit'] = r.fun
            return self.post(m, prec(r.x)[0], s) + (info,)
        if rule == 'FLf':
            # the default's long-wave prior kept as a floor (T^2 spectrum at its own REML scale),
            # a damped-oscillator peak added on top by REML: prior covariance never below the floor
            kap = self.kap

            def c0(a):
                P, ld = self.spectral(10**a / kap**2)
                return self.crit(y, Aty, P, ld, s)
            g0 = np.linspace(-8, 4, 25)
            v0 = [c0(a) for a in g0]
            i0 = int(np.argmin(v0))
            a0 = minimize_scalar(c0, bounds=(g0[max(i0 - 1, 0)], g0[min(i0 + 1, 24)]), method='bounded',
                                 options=dict(xatol=0.01)).x

            def precfl(th):
                return self.spectral(10**a0 / kap**2 + 10**th[0] / ((kap - 10**th[1])**2 + 10**th[2] * kap + 1e-12))

            def cfl(th):
                P, ld = precfl(th)
                return self.crit(y, Aty, P, ld, s)
            starts = [(a, b, c) for a in (-6, -4, -2) for b in np.log10(kap[[1, 4, 12]]) for c in (-3, -1)]
            best = min((cfl(np.array(st, float)), st) for st in starts)
            r = minimize(cfl, np.array(best[1], float), method='Nelder-Mead',
                         options=dict(xatol=0.02, fatol=1e-3, maxiter=300))
            info['th'] = r.x
            return self.post(m, precfl(r.x)[0], s) + (info,)
        if rule in ('EVSf', 'EVSHf'):
            # choose between the default (1 hyperparameter) and the peaked spectrum (3) by the
            # restricted likelihood with an AIC charge per hyperparameter (EVSf) or without (EVSHf)
            a = self.fit('D2f', m, s_ls)
            b = self.fit('SHOf', m, s_ls)
            pen = 2.0 if rule == 'EVSf' else 0.0
            pick = b if b[4]['crit'] + 3 * pen < a[4]['crit'] + 1 * pen else a
            pick[4]['picked_sho'] = pick is b
            pick[4]['dcrit'] = b[4]['crit'] - a[4]['crit']
            return pick
        if rule in ('SD2f', 'SGD2f'):
            return self.fit_full(rule, m, s) + (info,)
        raise ValueError(rule)

    # ---- full model: unknowns f(1..N-2), S (P), gamma (P), e2, e3 -----------------------------
    def full(self):
        if self._full is not None:
            return self._full
        mod = self.mod
        N, P, k, O = mod.N, mod.P, mod.k, mod.O
        n = mod.n_f
        nz = n + 2 * P + 2
        A = np.zeros((4 * P, nz))
        for p in range(P):
            for j in range(4):
                row = 4 * p + j
                col = p + k[j]
                if 0 < col < N - 1:
                    A[row, col - 1] = 1
                A[row, n + p] = 1
                A[row, n + P + p] = O[j]
                if j in (1, 2):
                    A[row, n + 2 * P + j - 1] = 1
        # null vector: f += bow, the rest compensates exactly
        zf = mod.bow[1:-1]
        rest = np.linalg.lstsq(A[:, n:], -A[:, :n] @ zf, rcond=None)[0]
        z0 = np.concatenate([zf, rest])
        gsel = np.zeros(nz); gsel[:n] = mod.bow[1:-1]
        T = np.eye(nz) - np.outer(z0, gsel) / (gsel @ z0)
        DS = dmat(P, 2)
        self._full = dict(A=A, AtA=A.T @ A, T=T, n=n, P=P, nz=nz, DtD=DS.T @ DS)
        return self._full

    def fit_full(self, rule, m, s):
        F = self.full()
        A, AtA, n, P, nz = F['A'], F['AtA'], F['n'], F['P'], F['nz']
        y = m.reshape(-1)
        Aty = A.T @ y
        Pf2 = self.Pf['D2']
        DtD = F['DtD']
        nS = P - 2

        def Pi(th):
            Pm = np.zeros((nz, nz))
            Pm[:n, :n] = 10**(2 * th[0]) * Pf2
            Pm[n:n + P, n:n + P] = 10**(2 * th[1]) * DtD
            ld = n * 2 * th[0] * np.log(10) + self.ldP['D2'] + nS * 2 * th[1] * np.log(10)
            if len(th) > 2:
                Pm[n + P:n + 2 * P, n + P:n + 2 * P] = 10**(2 * th[2]) * DtD
                ld += nS * 2 * th[2] * np.log(10)
            return Pm, ld

        def c(th):
            Pm, ld = Pi(th)
            try:
                cf = cho_factor(AtA + Pm)
            except np.linalg.LinAlgError:
                return 1e30
            x = cho_solve(cf, Aty); r = y - A @ x
            return (r @ r + x @ Pm @ x) / s**2 + 2 * np.sum(np.log(np.diag(cf[0]))) - ld
        dims = 2 if rule == 'SD2f' else 3
        grid = [np.array(t, float) for t in
                ([(a, b) for a in (-1, 0.5, 2) for b in (-2, 0, 2)] if dims == 2 else
                 [(a, b, cc) for a in (-1, 0.5, 2) for b in (-2, 0, 2) for cc in (0, 2, 4)])]
        best = min((c(t), i) for i, t in enumerate(grid))
        r = minimize(c, grid[best[1]], method='Nelder-Mead', options=dict(xatol=0.02, fatol=1e-3, maxiter=300))
        Pm, _ = Pi(r.x)
        cf = cho_factor(AtA + Pm)
        x = cho_solve(cf, Aty)
        T = F['T']
        xG = T @ x
        Minv = cho_solve(cf, np.eye(nz))
        Sig = s**2 * T @ Minv @ T.T
        S = xG[n:n + P]; g = xG[n + P:n + 2 * P]
        return S, g, np.diag(Sig)[n:n + P].copy(), np.diag(Sig)[n + P:n + 2 * P].copy()


def deg(rad_e3):   # gamma in mrad -> 1e-3 deg
    return np.rad2deg(rad_e3 * 1e-3) * 1e3


def ex1(rules, batches=3):
    N = 69
    R = Rules(N)
    tr = example1()
    print(f"Example 1, noise on each reading, median of {batches} batches of 20 runs")
    print(" sigma rule   dS_max  dg_max(1e-3 deg)  cov2u_S   (per batch dS_max)   s/run")
    for sig in (0.1, 0.2, 0.3):
        for rule in rules:
            t0 = time.time()
            dS, dg, cv = [], [], []
            for b in range(batches):
                mx = gx = 0
                c = 0
                for r in range(20):
                    rng = np.random.default_rng(100000 * b + r + int(sig * 1000))
                    m = simulate(tr, N, sig, rng)
                    s_ls, _ = R.mod.sigma_ls(m)
                    S, g, vS, vg, _ = R.fit(rule, m, s_ls)
                    eS = S - tr['S']; eg = g - tr['g']; eg -= eg.mean()
                    mx = max(mx, np.abs(eS).max()); gx = max(gx, np.abs(eg).max())
                    c += np.mean(np.abs(eS) <= 2 * np.sqrt(vS))
                dS.append(mx); dg.append(deg(gx)); cv.append(c / 20)
            print(f" {sig:.1f}  {rule:6s} {np.median(dS):5.2f}   {np.median(dg):5.2f}            {np.mean(cv):.3f}"
                  f"     ({' '.join(f'{a:.2f}' for a in dS)})   {(time.time() - t0) / (20 * batches):.2f}",
                  flush=True)


def cov(rules, Ns, sigmas, seeds):
    print(f"random multi-harmonic profiles (fs.truth_random), {seeds} seeds per cell; fraction of points"
          " with |S - S_true| <= 2 u_S (pooled), worst seed, RMS error median, max error, median u_S")
    for N in Ns:
        R = Rules(N)
        for sig in sigmas:
            for rule in rules:
                t0 = time.time()
                st = []
                for sd in range(seeds):
                    rng = np.random.default_rng(1000 * N + sd + int(sig * 1e4))
                    tr = truth_random(N, rng)
                    m = simulate(tr, N, sig, rng)
                    s_ls, _ = R.mod.sigma_ls(m)
                    S, g, vS, vg, _ = R.fit(rule, m, s_ls)
                    e = S - tr['S']; eg = g - tr['g']
                    st.append((np.mean(np.abs(e) <= 2 * np.sqrt(vS)), np.sqrt(np.mean(e**2)), np.abs(e).max(),
                               np.median(np.sqrt(vS)), np.mean(np.abs(eg) <= 2 * np.sqrt(vg))))
                a = np.array(st)
                print(f" N={N:5d} sig={sig:.2f} {rule:6s} covS={a[:, 0].mean():.3f} (worst {a[:, 0].min():.2f})"
                      f" rmsS={np.median(a[:, 1]):.3f} maxS={a[:, 2].max():.2f} medu={np.median(a[:, 3]):.3f}"
                      f" covG={a[:, 4].mean():.3f}  {(time.time() - t0) / seeds:.2f} s/seed", flush=True)
                np.save(f"/tmp/ex1r_cov_{N}_{sig}_{rule}.npy", a)


if __name__ == '__main__':
    what = sys.argv[1]
    rules = sys.argv[2].split(',')
    if what == 'ex1':
        ex1(rules, int(sys.argv[3]) if len(sys.argv) > 3 else 3)
    else:
        cov(rules, [int(a) for a in sys.argv[3].split(',')], [float(a) for a in sys.argv[4].split(',')],
            int(sys.argv[5]))
