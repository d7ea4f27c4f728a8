"""Continuum geodesics: distances by a Chebyshev pseudospectral transcription with
degree doubling (`spectral`, on the nodes and matrices of `solvers.chebyshev`) and the
exponential and logarithm maps (`expmap`)."""
