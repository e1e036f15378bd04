"""Discovery: a passive port-Hamiltonian correction found when no library candidate explains the residual."""
