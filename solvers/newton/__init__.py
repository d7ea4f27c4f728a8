"""Batched Newton solves of the discrete energy: the Newton iteration (`energy`), the
driver that solves every (pair, seed) problem of a call as one batch (`driver`), the
interior point for slack reformulations of non-smooth metrics (`interior`), their KKT
residual (`kkt`), block-tridiagonal solves (`block_tridiagonal`) and the array backends
(`backends`)."""
