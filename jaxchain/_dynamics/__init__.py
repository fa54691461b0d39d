"""The dynamics of the localized states (Section 3.3 of the paper): time delays,
periodic or irregular, and the scenes of Figs. 5-10."""
