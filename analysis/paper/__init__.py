"""The paper as data: published values (`published`), GRIM/GRIMMER (`grim`), the consistency audit (`audit`), the
reconstructed survey (`reconstruct`), the reference cohort (`cohort`) and the reproduction comparison
(`reproduction`). See docs/paper_reproduction.md."""
