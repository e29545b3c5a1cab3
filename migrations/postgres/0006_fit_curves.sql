-- The measured-vs-model curve of each fit (issue 19, point 4): see
-- migrations/sqlite/0006_fit_curves.sql (same shape).
CREATE TABLE fit_curves (
    fit_id     BIGINT PRIMARY KEY REFERENCES fits (id) ON DELETE CASCADE,
    curve_json JSONB NOT NULL
);
