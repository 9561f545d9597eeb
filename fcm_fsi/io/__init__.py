"""Output: logging, CSV time series, XDMF fields, HDF5 checkpoints, stage timing."""
