"""The physics of the chain: its parameters, friction laws, topology and coupling,
the vector field of eq. (5), initial conditions and the stick criterion. Nothing
here knows about solvers; every layer above (engine, observers, studies, front
ends) reads the chain only through these modules."""
