"""Rule-based construction baselines the paper compares ConAg against (§5.2).

`lattice` is the Jones & Mataric (2003)-style reactive lattice world (R1),
`rules` generates its transition rule sets for square rings (R2, Fig. 10) and
`perturb` reproduces the failure cases of Fig. 12 and Fig. 14 (R4).
"""
