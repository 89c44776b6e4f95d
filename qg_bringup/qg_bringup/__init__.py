"""The stack's command line, ``qgl``: bring the processes up, run episodes and training runs, the
demo, recordings and policy files. Above every other package: nothing but tests imports it."""
