import numpy as np
from scipy.optimize import minimize_scalar
from scipy.linalg import cho_factor, cho_solve

def geometry(N, s=(1,1,5), dx=5.0):
    k = np.array([0, s[0], s[0]+s[1], s[0]+s[1]+s[2]])
    return k, k*dx, N - k[-1]

def Qbasis(O):
    X = np.column_stack([np.ones(4), O])
    U, _, _ = np.linalg.svd(X, full_matrices=True)
    return U[:, 2:]

def truth_random(N, rng, dx=5.0, s=(1,1,5), fmax=None):
    k, O, P = geometry(N, s, dx)
    L0 = (N-1)*dx; L = (P-1)*dx
    x = np.arange(N)*dx
    xs = x[:P]
    def harm(xx, length, J, amp, qlo, qhi):
        out = np.zeros_like(xx)
        for _ in range(J):
            q = rng.uniform(qlo, qhi); a = rng.uniform(*amp); ph = rng.uniform(0, 2*np.pi)
            out += a*np.sin(2*np.pi*q*xx/length + ph)
        return out
    S = harm(xs, L, rng.integers(2,5), (0.5, 6.0), 0.5, 8)
    g_mrad = harm(xs, L, rng.integers(2,4), (0.02, 0.2), 0.5, 6)   # mrad (=um/mm)
    f = harm(x, L0, rng.integers(2,5), (0.3, 4.0), 1, 15)
    # put f in gauge: ends zero, no bow component
    t = x/L0; bow = t*(1-t)
    B = np.column_stack([np.ones(N), t, t*t])
    # find a,b,c so that f+B@abc has f0=fN=0 and bow.(f+..)=0
    Cm = np.vstack([B[0], B[-1], bow @ B])
    rhs = -np.array([f[0], f[-1], bow @ f])
    abc = np.linalg.solve(Cm, rhs)
    f = f + B @ abc
    e = np.array([0.0, rng.normal(0, 0.5), rng.normal(0, 0.5), 0.0])
    return dict(S=S, g=g_mrad, f=f, e=e)

def example1(N=69, dx=5.0, s=(1,1,5)):
    k, O, P = geometry(N, s, dx)
    L0 = (N-1)*dx; L = (P-1)*dx
    x = np.arange(N)*dx; xs = x[:P]
    S = 8.075*np.sin(4*np.pi/L*xs) + 5.7*np.sin(6*np.pi/L*xs + 5/18*np.pi) - 1.9*np.sin(14*np.pi/L*xs + np.pi/2)
    gdeg = 0.008*np.sin(2*np.pi/L*xs + np.pi/3) - 0.014*np.sin(4*np.pi/L*xs + np.pi/4) + 0.005*np.sin(10*np.pi/L*xs + 7/12*np.pi)
    g_mrad = np.deg2rad(gdeg)*1e3
    f = 5*np.sin(10*np.pi/L0*x)
    return dict(S=S, g=g_mrad, f=f, e=np.zeros(4))

def simulate(tr, N, sigma, rng, dx=5.0, s=(1,1,5)):
    k, O, P = geometry(N, s, dx)
    m = np.empty((P, 4))
    for j in range(4):
        m[:, j] = tr['f'][np.arange(P)+k[j]] + tr['S'] + O[j]*tr['g'] + tr['e'][j]
    return m + rng.normal(0, sigma, m.shape)

class Model:
    def __init__(self, N, dx=5.0, s=(1,1,5)):
        self.N = N; self.dx = dx
        k, O, P = geometry(N, s, dx)
        self.k, self.O, self.P = k, O, P
        Q = Qbasis(O); self.Q = Q
        n_f = N - 2  # f(0), f(N-1) pinned
        nx = n_f + 2
        A = np.zeros((2*P, nx))
        for n in range(P):
            for j in range(4):
                col = n + k[j]
                if 0 < col < N-1:
                    A[2*n:2*n+2, col-1] += Q[j, :]
            A[2*n, n_f] = 1; A[2*n+1, n_f+1] = 1
        self.A = A; self.n_f = n_f; self.nx = nx
        self.AtA = A.T @ A
        D2 = np.zeros((N-2, N))
        for i in range(N-2):
            D2[i, i:i+3] = [1, -2, 1]
        D2 = D2[:, 1:-1]
        D1 = np.zeros((N-1, N))
        for i in range(N-1):
            D1[i, i:i+2] = [-1, 1]
        D1 = D1[:, 1:-1]
        self.pens = {}
        def embed(Pf):
            Pm = np.zeros((nx, nx)); Pm[:n_f, :n_f] = Pf; return Pm
        self.pens['I'] = embed(np.eye(n_f))
        self.pens['D1'] = embed(D1.T @ D1)
        self.pens['D2'] = embed(D2.T @ D2)
        L0 = (N-1)*dx
        t = np.arange(N)/(N-1); self.bow = t*(1-t)
        self.nvec = np.concatenate([self.bow[1:-1], Q.T @ (O**2) / L0**2])
        X = np.column_stack([np.ones(4), O])
        W = np.linalg.solve(X.T @ X, X.T)   # 2x4: rows give S, gamma from 4 residuals
        self.W = W
        # e from eta with e1=e4=0: Q[[1,2],:].T @ [e2,e3] = eta
        self.Einv = np.linalg.inv(Q[[1,2], :].T)

    def y(self, m):
        return (m @ self.Q).reshape(-1)

    def gauge_T(self):
        # x_G = T x : x - (bow.f / bow.bow_f) nvec  where bow.f uses full f (ends 0)
        g = np.zeros(self.nx); g[:self.n_f] = self.bow[1:-1]
        c = g @ self.nvec
        return np.eye(self.nx) - np.outer(self.nvec, g)/c

    def lin_SG(self):
        """matrices mapping (m, x_G) -> S, gamma: S = Wm - G x"""
        P, N, k = self.P, self.N, self.k
        G_S = np.zeros((P, self.nx)); G_g = np.zeros((P, self.nx))
        E = np.zeros((4, self.nx)); E[1:3, self.n_f:] = self.Einv
        for n in range(P):
            row = np.zeros((4, self.nx))
            for j in range(4):
                col = n + k[j]
                if 0 < col < N-1: row[j, col-1] = 1
            row += E
            G_S[n] = self.W[0] @ row; G_g[n] = self.W[1] @ row
        return G_S, G_g

    def solve(self, m, pen, lam, sigma):
        M = self.AtA + lam**2 * self.pens[pen]
        if pen != 'I' and False: pass
        cf = cho_factor(M)
        y = self.y(m)
        x = cho_solve(cf, self.A.T @ y)
        T = self.gauge_T()
        xG = T @ x
        Minv = cho_solve(cf, np.eye(self.nx))
        SigG = sigma**2 * T @ Minv @ T.T
        G_S, G_g = self.lin_SG()
        S = m @ self.W[0] - G_S @ xG
        g = m @ self.W[1] - G_g @ xG
        CovS = sigma**2 * (self.W[0] @ self.W[0]) * np.eye(self.P) + G_S @ SigG @ G_S.T
        Covg = sigma**2 * (self.W[1] @ self.W[1]) * np.eye(self.P) + G_g @ SigG @ G_g.T
        f = np.concatenate([[0], xG[:self.n_f], [0]])
        uf = np.sqrt(np.concatenate([[0], np.diag(SigG)[:self.n_f], [0]]))
        return dict(S=S, g=g, f=f, CovS=CovS, Covg=Covg, uS=np.sqrt(np.diag(CovS)), ug=np.sqrt(np.diag(Covg)), uf=uf, x=x)

    def sigma_ls(self, m):
        # redundancy: unregularised LS residual
        M = self.AtA + 1e-10*np.eye(self.nx)*np.trace(self.AtA)/self.nx
        y = self.y(m)
        x = np.linalg.lstsq(self.A, y, rcond=None)[0]
        r = y - self.A @ x
        dof = 2*self.P - (self.N - 2) - 2 + 1
        return np.sqrt(r @ r / dof), dof

    def reml(self, m, pen, sigma_fixed=None, lo=-6, hi=6):
        y = self.y(m); Aty = self.A.T @ y
        Pm = self.pens[pen]; r = self.n_f
        mrows = len(y); p = 2
        def crit(ll):
            lam = 10**ll
            M = self.AtA + lam**2 * Pm
            try:
                cf = cho_factor(M)
            except Exception:
                return 1e30
            x = cho_solve(cf, Aty)
            res = y - self.A @ x
            q = res @ res + lam**2 * x @ Pm @ x
            logdet = 2*np.sum(np.log(np.diag(cf[0])))
            if sigma_fixed is None:
                return (mrows - p)*np.log(q) + logdet - r*np.log(lam**2)
            return q/sigma_fixed**2 + logdet - r*np.log(lam**2)
        grid = np.linspace(lo, hi, 61)
        vals = [crit(g) for g in grid]
        i = int(np.argmin(vals))
        a, b = grid[max(i-1,0)], grid[min(i+1,len(grid)-1)]
        r_ = minimize_scalar(crit, bounds=(a, b), method='bounded')
        ll = r_.x
        lam = 10**ll
        # sigma estimate (profiled)
        M = self.AtA + lam**2 * Pm
        x = np.linalg.solve(M, Aty); res = y - self.A @ x
        q = res @ res + lam**2 * x @ Pm @ x
        s2 = q/(mrows - p)
        return lam, np.sqrt(s2), (i == 0 or i == len(grid)-1)

def reml2(mod, m, sigma_fixed, grid=np.linspace(-4, 5, 19)):
    """two-component precision: lam1^2 I + lam2^2 D2tD2; returns (l1, l2)"""
    y = mod.y(m); Aty = mod.A.T @ y
    I = mod.pens['I']; D = mod.pens['D2']
    mrows = len(y); p = 2
    def crit(l1, l2):
        Pm = (10**l1)**2 * I + (10**l2)**2 * D
        M = mod.AtA + Pm
        try: cf = cho_factor(M)
        except Exception: return 1e30
        x = cho_solve(cf, Aty); res = y - mod.A @ x
        q = res @ res + x @ Pm @ x
        logdet = 2*np.sum(np.log(np.diag(cf[0])))
        # log det Pm (prior precision, in sigma^2 units)
        ev = np.linalg.eigvalsh(Pm[:mod.n_f, :mod.n_f])
        return q/sigma_fixed**2 + logdet - np.sum(np.log(ev))
    best = None
    for a in grid:
        for b in grid:
            v = crit(a, b)
            if best is None or v < best[0]: best = (v, a, b)
    from scipy.optimize import minimize
    r = minimize(lambda z: crit(z[0], z[1]), [best[1], best[2]], method='Nelder-Mead', options=dict(xatol=0.01, fatol=1e-4))
    return 10**r.x[0], 10**r.x[1]

def solve_P(mod, m, Pm, sigma):
    mod.pens['_tmp'] = Pm
    return mod.solve(m, '_tmp', 1.0, sigma)

def lowmodes(mod, K):
    N = mod.N; t = np.arange(N)/(N-1)
    B = np.column_stack([np.sin(np.pi*j*t) for j in range(1, K+1)])
    return B[1:-1] * np.sqrt(2.0/N)   # unit-ish norm columns in reduced coords

def reml_cov(mod, m, Kfun, theta0, sigma):
    """generic REML over log-params theta of prior covariance Kf(theta) (reduced f)"""
    from scipy.optimize import minimize
    y = mod.y(m); Af = mod.A[:, :mod.n_f]; X = mod.A[:, mod.n_f:]
    def crit(th):
        Kf = Kfun(th)
        V = sigma**2*np.eye(len(y)) + Af @ Kf @ Af.T
        try: cV = cho_factor(V)
        except Exception: return 1e30
        Vi_y = cho_solve(cV, y); Vi_X = cho_solve(cV, X)
        XVX = X.T @ Vi_X
        b = np.linalg.solve(XVX, X.T @ Vi_y)
        r = y - X @ b
        q = r @ cho_solve(cV, r)
        return 2*np.sum(np.log(np.diag(cV[0]))) + np.linalg.slogdet(XVX)[1] + q
    best = None
    r = minimize(crit, theta0, method='Nelder-Mead', options=dict(xatol=0.02, fatol=1e-4, maxiter=400))
    return r.x, r.fun

def solve_cov(mod, m, Kf, sigma):
    # posterior with prior cov Kf on f_red, flat on eta
    Pm = np.zeros((mod.nx, mod.nx)); Pm[:mod.n_f, :mod.n_f] = sigma**2*np.linalg.inv(Kf)
    return solve_P(mod, m, Pm, sigma)

def add_D3(mod):
    N = mod.N
    D3 = np.zeros((N-3, N))
    for i in range(N-3): D3[i, i:i+4] = [-1, 3, -3, 1]
    D3 = D3[:, 1:-1]
    Pm = np.zeros((mod.nx, mod.nx)); Pm[:mod.n_f, :mod.n_f] = D3.T @ D3 + 1e-9*np.eye(mod.n_f)
    mod.pens['D3'] = Pm
