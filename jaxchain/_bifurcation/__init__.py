"""Analysis of steady sliding and of periodic orbits: Hopf boundary, shooting,
Floquet multipliers, pseudo-arclength continuation, folds of limit cycles, and design
with their parameter derivatives."""
