"""The campaign: its engine (a typed state machine over events), the seeding and reduction
steps, the decision composed of the stages, compile-ahead, and the one driving loop."""
