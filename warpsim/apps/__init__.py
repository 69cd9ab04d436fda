"""The applications built on the package: the ``warpsim`` command line (:mod:`.cli`) and its
throughput measure ``warpsim bench`` (:mod:`.bench`). Nothing in the package imports them."""
