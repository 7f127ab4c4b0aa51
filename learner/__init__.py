"""Learning the ground effect: datasets, the network, offline and online training, diagnosis."""
