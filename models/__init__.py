"""Models shipped with drake_hybrid (found through package.xml as package://drake_hybrid/...)."""
