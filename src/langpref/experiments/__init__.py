"""The paper's experiments, each reproducible from one command (`langpref experiment NAME`)."""
