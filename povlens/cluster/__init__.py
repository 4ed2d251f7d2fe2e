"""Lens samples rendered on a Dask cluster (``povlens render --scheduler ADDRESS``).

:mod:`povlens.cluster.bundle` packs what a worker needs (the render folder's plan,
pupil table and wrappers, the lens file, the scene's folder with its include files and
image maps) and unpacks it on the worker; :mod:`povlens.cluster.worker` is the task
(one lens sample, rendered by the same code as a local render); :mod:`povlens.cluster.render`
is the client (submit, write each sample as it comes back, composite).  Dask is imported
only here, and only when a scheduler is given.
"""
