"""The model and what a solve applies: `model` (`Model`: build, save, load, solve), `jaw` (the
jaw as a joint), `local` (local fits' pieces), `detail` (the detail blend), `take_prior` (a
take's prior on the global fit), `placement` (is a take the model's size?) and `rig` (an actor's
rig solved through a model). Deeper than the options' edge: it trusts what it is given."""
