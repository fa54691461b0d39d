"""The event-driven non-smooth reference: stick and slip as separate modes, switched
at events located by root finding (diffrax `Event` with an optimistix root finder)."""
