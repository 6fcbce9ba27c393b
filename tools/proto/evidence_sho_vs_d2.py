# Restricted likelihood of the peaked prior (SHOf) minus the default (D2f), with the SHO prior's
# coverage of u_S, on random profiles at N = 69 and on Example 1 (README: "evidence cannot guard").
import sys; sys.path.insert(0, __file__.rsplit('/', 1)[0])
from ex1r import *
R=Rules(69); tr0=example1()
for sig in (0.05,0.1):
    out=[]
    for sd in range(20):
        rng=np.random.default_rng(1000*69+sd+int(sig*1e4)); tr=truth_random(69,rng); m=simulate(tr,69,sig,rng)
        s,_=R.mod.sigma_ls(m); S,g,vS,vg,info=R.fit('EVSHf',m,s)
        a=R.fit('SHOf',m,s); cov=np.mean(np.abs(a[0]-tr['S'])<=2*np.sqrt(a[2]))
        out.append((info['dcrit'],cov))
    print('random',sig,' '.join(f'{d:+.1f}/{c:.2f}' for d,c in out),flush=True)
for sig in (0.1,0.3):
    ds=[]
    for r in range(10):
        rng=np.random.default_rng(r+int(sig*1000)); m=simulate(tr0,69,sig,rng); s,_=R.mod.sigma_ls(m)
        ds.append(R.fit('EVSHf',m,s)[4]['dcrit'])
    print('ex1',sig,' '.join(f'{d:+.1f}' for d in ds),flush=True)
