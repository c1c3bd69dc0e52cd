"""Pixel selection: DSO-style block-gradient selection on RGB (:mod:`.rgb`) and the event
selection of Section II-B filtered through the ATS (:mod:`.events`)."""
