-- The measured-vs-model curve of each fit (issue 19, point 4): stored with the fit so a page
-- draws it without refitting. One row per fit, thinned to a plot's width
-- (`models::report::FitCurve`); fits written before this migration have none.
CREATE TABLE fit_curves (
    fit_id     INTEGER PRIMARY KEY REFERENCES fits (id) ON DELETE CASCADE,
    curve_json TEXT NOT NULL CHECK (json_valid(curve_json))
) STRICT;
