"""The models: the primary GP of f, the noise laws and noise field, their fits and their
posterior over the grids. Nothing here knows a policy or a campaign."""
