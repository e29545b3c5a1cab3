-- The fleet's prior per joint and parameter, learned from the workshop fits in the store
-- (issue 37, point 3; models::lift::fleet_prior): versioned, each version kept. A lift or
-- gauge fit uses the newest version of its pantograph type for the joints it does not report
-- and records which in `fits.prior_version` (and `fit.prior` of its result); NULL: a fit under
-- no stored prior (workshop fits, fits written before this migration, or version 0: the type
-- file's Table 4 ± floor). A version is published only by an explicit relearn (`POST
-- /v1/fleet/prior`, `pantowatch prior learn`) whose prior differs from the newest by more than
-- `[fleet_prior] version_tolerance_relative`.
-- Same shape as migrations/postgres/0009_fleet_priors.sql.

CREATE TABLE fleet_priors (
    version           INTEGER PRIMARY KEY CHECK (version > 0),
    model             TEXT NOT NULL CHECK (length(model) > 0),
    learned_at        TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')),
    source            TEXT NOT NULL CHECK (source IN ('learned', 'type_file')),
    n_units           INTEGER NOT NULL CHECK (n_units >= 0),
    floor_relative_sd REAL NOT NULL,
    fit_sd_scale      REAL NOT NULL
) STRICT;
CREATE INDEX fleet_priors_model ON fleet_priors (model, version);

-- One row per joint and parameter of a version (Table 4 units, θ/θ₀).
CREATE TABLE fleet_prior_params (
    version      INTEGER NOT NULL REFERENCES fleet_priors (version),
    joint        TEXT NOT NULL CHECK (length(joint) > 0),
    param        TEXT NOT NULL CHECK (param IN ('viscous', 'dry')),
    mean_ratio   REAL NOT NULL,
    sd_ratio     REAL NOT NULL,
    spread_ratio REAL NOT NULL,
    n_fits       INTEGER NOT NULL CHECK (n_fits >= 0),
    learned      INTEGER NOT NULL CHECK (learned IN (0, 1)),
    PRIMARY KEY (version, joint, param)
) STRICT;

ALTER TABLE fits ADD COLUMN prior_version INTEGER;
