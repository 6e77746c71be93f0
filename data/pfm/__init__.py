"""The PFM scan shipped with noisebo, as package data (``noisebo.scans``; see README.md here).
A config names it as data/pfm/PTO_Funakubo0003.h5, or by its file name."""
