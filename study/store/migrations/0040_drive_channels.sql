-- Extra drive-log channels (docs/drive_logs.md): a log mapping may keep channels beyond the canonical drive log
-- (pedals, steering, lateral position, gaze, ...). Each is stored as a DOUBLE column of drive_samples named after
-- the channel (added by the import with ALTER TABLE when first seen) and registered here with the unit of its
-- stored values. Channel names are lower-case identifiers that are neither canonical columns nor SQL keywords.
CREATE TABLE drive_channels (
    channel         VARCHAR PRIMARY KEY CHECK (regexp_full_match(channel, '^[a-z][a-z0-9_]{0,62}$')),
    unit            VARCHAR NOT NULL CHECK (length(unit) BETWEEN 1 AND 40),     -- '1' for a unitless number
    description     VARCHAR,
    added_at        TIMESTAMP NOT NULL DEFAULT (current_timestamp AT TIME ZONE 'UTC')
);
