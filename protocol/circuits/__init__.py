"""Boolean circuits (:mod:`.boolean`) and the one both suites evaluate (:mod:`.paths`)."""
