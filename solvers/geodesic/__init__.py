"""The solve of discrete geodesics: the public entry points (`solve`), the solver of
checked pairs that picks Newton or IPOPT and keeps the best seed (`pair_solver`), accuracy
on request (`tolerance`), many pairs in chunks, processes or Ray tasks (`batches`,
`distributed`), and the paper authors' Adam baseline for comparison (`baseline`)."""
