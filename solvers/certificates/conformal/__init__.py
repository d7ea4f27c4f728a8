"""The certificate of a conformal metric ``F(q, v) = f(q) |v|`` in any dimension
(`certificate`), its plane step on a grid of ``(s, r)`` cells (`grid`) and the split of a
factor that is a sum of parts (`split`)."""
