"""Sweeps: many runs of one scene with varied parameters, on Dask (`gyro-sim sweep`).

A sweep file (:mod:`.spec`) names a base scene, the parameters to vary by key path into the
scene mapping (a grid, or random draws with a seed), the run (integrator, horizon, chunk) and
what to measure. Every point is one independent simulation (:mod:`.point`); points go in
batches to a Dask cluster (:mod:`.execute`: a LocalCluster by default, any scheduler by
address); each finished batch is written at once as a Parquet part, so a sweep that dies
resumes. The table, a Markdown summary and a PNG map come from :mod:`.results`; the shipped
sweeps (config/sweeps/) are checked against the formulas of :mod:`.theory`.

Determinism: a point's row depends only on the sweep file and the point's index (the seed of
point i is ``SeedSequence(seed, spawn_key=(i,))``), never on the batch, the worker or the
order, so a parallel run gives the serial run's table bit for bit (all columns but the
measured ``cpu_s``).
"""
