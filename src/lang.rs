//! The robot languages skillpost writes, as plain values: their names, and what reading an IRL
//! file needs to know of each ([`Language::syntax`]). Everything else a language decides is its
//! profile's (`emit`), which the stages before `emit` never see (ARCHITECTURE.md, the layers).

use crate::template::Syntax;

/// A robot language skillpost writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Language {
    Krl,
    Rapid,
    UrScript,
}

impl Language {
    pub const ALL: [Language; 3] = [Language::Krl, Language::Rapid, Language::UrScript];

    /// `KRL`, `RAPID` or `URScript`, any case (surrounding whitespace ignored).
    pub fn parse(s: &str) -> Option<Language> {
        let s = s.trim();
        Language::ALL
            .into_iter()
            .find(|l| l.name().eq_ignore_ascii_case(s))
    }

    /// The language's name as the blackboard and the listings write it.
    pub fn name(self) -> &'static str {
        match self {
            Language::Krl => "KRL",
            Language::Rapid => "RAPID",
            Language::UrScript => "URScript",
        }
    }

    /// How IRL templates of this language are read.
    pub fn syntax(self) -> Syntax {
        match self {
            Language::Krl => Syntax::KRL,
            Language::Rapid => Syntax {
                comment: b'!',
                aggregates: false,
                case_sensitive: false,
            },
            Language::UrScript => Syntax {
                comment: b'#',
                aggregates: false,
                case_sensitive: true,
            },
        }
    }
}

impl std::fmt::Display for Language {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The variable the KRL and RAPID programs keep a selection's branch in (`SKP_BRANCH`): no
/// signal may be named so (the blackboard reader refuses it).
pub const BRANCH_VAR: &str = "SKP_BRANCH";
