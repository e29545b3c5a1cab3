-- The fleet's prior per joint and parameter, learned from the workshop fits in the store
-- (issue 37, point 3; models::lift::fleet_prior): versioned, each version kept. A lift or
-- gauge fit uses the newest version of its pantograph type for the joints it does not report
-- and records which in `fits.prior_version` (and `fit.prior` of its result); NULL: a fit under
-- no stored prior (workshop fits, fits written before this migration, or version 0: the type
-- file's Table 4 ± floor). A version is published only by an explicit relearn (`POST
-- /v1/fleet/prior`, `pantowatch prior learn`) whose prior differs from the newest by more than
-- `[fleet_prior] version_tolerance_relative`.
-- Same shape as migrations/sqlite/0009_fleet_priors.sql.

CREATE TABLE fleet_priors (
    version           BIGINT PRIMARY KEY CHECK (version > 0),
    model             TEXT NOT NULL CHECK (length(model) > 0),
    learned_at        TIMESTAMPTZ NOT NULL DEFAULT now(),
    source            TEXT NOT NULL CHECK (source IN ('learned', 'type_file')),
    n_units           BIGINT NOT NULL CHECK (n_units >= 0),
    floor_relative_sd DOUBLE PRECISION NOT NULL,
    fit_sd_scale      DOUBLE PRECISION NOT NULL
);
CREATE INDEX fleet_priors_model ON fleet_priors (model, version);

-- One row per joint and parameter of a version (Table 4 units, θ/θ₀).
CREATE TABLE fleet_prior_params (
    version      BIGINT NOT NULL REFERENCES fleet_priors (version),
    joint        TEXT NOT NULL CHECK (length(joint) > 0),
    param        TEXT NOT NULL CHECK (param IN ('viscous', 'dry')),
    mean_ratio   DOUBLE PRECISION NOT NULL,
    sd_ratio     DOUBLE PRECISION NOT NULL,
    spread_ratio DOUBLE PRECISION NOT NULL,
    n_fits       BIGINT NOT NULL CHECK (n_fits >= 0),
    learned      BOOLEAN NOT NULL,
    PRIMARY KEY (version, joint, param)
);

ALTER TABLE fits ADD COLUMN prior_version BIGINT;
