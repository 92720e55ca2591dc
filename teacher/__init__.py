"""The ConAg teacher (paper §5): reinforces students' construction decisions.

Not implemented yet: it arrives with issue #5. The bus keys and messages it will use
(`Decision`, `Reinforcement`) are already in `protocol/`.
"""
