"""Measurement tables and mixtures: pigments from measured colours, and what to measure next.

The table family of `diffwash.fit` (docs/fitting.md, "Measurement tables"; docs/mixing.md):

- `fit_table(csv)`: every pigment of a single-pigment RGB table (`read_table`, a `MeasurementTable`;
  `read_ntu_wpsm` for the NTU data) in one call (`TableFit`).
- `fit_mixtures(measurements, model=MixModel(...))`: mixable pigments, per band, fitted jointly to
  single paints, mixtures and glaze stacks (`MixtureFit`), with a posterior whose 90% regions
  `uncertainty_lines` prints; `pair_folds` and `score_library` measure how it predicts pairs it never saw mixed.
- `suggest(library, candidates, n, queries)`: the swatches whose measurement would shrink those regions
  most (`Suggestions` of `Pick`s; `write_suggestions`).

Inside: `_table` (RGB tables and their fit), `_mixfit` (the joint fit), `_pairs` (pair terms), `_seen`
(the CIEDE2000 refinement), `_priors` (population priors), `_posterior` (the Laplace posterior and its
calibration), `_suggest`. Shared with the other families: `diffwash.fit._kmfit` (the single-pigment
Kubelka-Munk fit) and `diffwash.fit._bandlsq` (the band Levenberg-Marquardt).
"""

import lazy_loader as _lazy

# The names of `__init__.pyi`, each imported from its module when first used.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
