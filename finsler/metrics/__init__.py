"""Metrics: the base class every metric subclasses (`base`: `Metric`, its task and
training settings, its checks `checks` and length quadrature `quadrature`), the paper's
task metrics (`paper`: Matsumoto, car-like, Panda pole, with the Panda kinematics in
`panda`) and the closed-form references."""
