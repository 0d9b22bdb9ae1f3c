"""Model files of drake_hybrid (data only); see drake_hybrid.station.parsing."""
