"""Verification of the physics (`woundsweep verify`): manufactured solutions with their
rates (`mms`), the slit's closed-form closure and the closures' identities (`slit`),
objectivity (`objectivity`), contact known answers (`contact_cases`), on the production
forms and solvers through `bvp`; the registry of cases (`cases`) and their report
(`report`). docs/validation.md, "Verification", has the table and the figures."""
