"""The network bridge between a campaign and an instrument PC, and the drivers "remote" and
"manual". ``bridge.client`` is the instrument PC's side: standard library only, copied alone."""
