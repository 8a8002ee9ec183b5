"""Teaching material: figure-sheet demos, guided tours, lattice scenes and the papers'
reproduction. The demo names live here so the command line lists them without loading
the demos."""

#: the teaching demos, in the order ``voxwarp reproduce`` runs them
DEMOS: tuple[str, ...] = ("massspring", "chainmail", "wires", "lattice", "compare", "registration")
#: one line per demo (``voxwarp demo --help``, the reproduction report)
DEMO_TITLES: dict[str, str] = {
    "massspring": "Mass-spring: explicit vs semi-implicit Euler",
    "chainmail": "3D ChainMail: propagation order and relaxation (thesis Figure 13)",
    "wires": "Wires: field scales, samples ignored, identity cost (wire paper Fig. 12, Tables 1-3)",
    "lattice": "Trilinear lattices: a bent volume, a torus of tubes, normals (GRAPP 2010)",
    "compare": "Mass-spring vs ChainMail on the same drag; CPU vs GPU (thesis Figures 12-13)",
    "registration": "A SimpleITK registration rendered through its displacement field",
}
