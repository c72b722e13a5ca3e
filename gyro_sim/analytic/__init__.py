"""The paper's closed-form results: chains of Lagrange gyroscopes (eqs 60-88), :mod:`.lagrange`."""
