"""Lens samples rendered on a Dask cluster (``povlens render --scheduler ADDRESS``).

:mod:`povlens.cluster.bundle` packs what a worker needs (the render folder's plan,
pupil table and wrappers, the lens file, the scene's folder with its include files and
image maps) and unpacks it on the worker; :mod:`povlens.cluster.worker` holds the tasks
(a group of lens samples rendered by the same code as a local render, several POV-Ray
processes in flight, and summed there; or one sample whose files come back);
:mod:`povlens.cluster.client` is the client (submit, write each group's partial sums
as they come back, composite; focus pulls through one client).  Dask is imported only
here, and only when a scheduler is given.
"""
