"""placeholder"""
def equilibrium(*a, **k): raise NotImplementedError
