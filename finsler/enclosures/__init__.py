"""Rigorous enclosures of a lowered CasADi function over boxes: interval arithmetic
(`intervals`, outward rounding) and affine arithmetic (`affine`), which keeps the
correlation of the inputs and bounds a function tighter on small boxes."""
