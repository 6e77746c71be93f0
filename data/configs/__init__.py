"""The campaign configurations shipped with noisebo, as package data (``noisebo.configs``):
`noisebo config` lists them, `noisebo config NAME` prints one, `noisebo run NAME` runs one."""
