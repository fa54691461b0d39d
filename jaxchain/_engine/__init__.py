"""The engine: integrating any ODE in chunks with diffrax and observing while
integrating (`simulate`, `observe`), the solvers and step-size controller, the
observers, the trajectories spread over devices (`lanes`) and Dask workers
(`cluster`), options, checks, failure statuses, result keys and kept programs. It
reads the chain only through `_physics`."""
