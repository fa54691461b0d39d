"""Analysis of what runs produce: the vocabulary of final states, time delays,
periodic or irregular, propagating fronts, and linear (Anderson) localization."""
