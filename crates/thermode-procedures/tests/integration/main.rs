//! Integration tests of thermode-procedures: the method of limits against its analytic line, the yes/no procedures'
//! recovery of the threshold, the staircase against PsychoPy's rules, QUEST+ against the `questplus` package, the
//! analysis maths and the shipped experiment files.

mod analysis;
mod experiments;
mod limits_line;
mod questplus_package;
mod recovery;
mod staircase_rules;
