"""Mistuned chains: how random stiffness mistuning (Anderson localization) acts on
the friction-localized states, and intentional mistuning chosen by gradient."""
