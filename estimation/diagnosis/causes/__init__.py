"""The catalogue of causes and the structural candidates: forms, ladders, sections split or added, unmerged couplings."""
