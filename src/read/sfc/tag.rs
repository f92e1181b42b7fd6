//! The tags the reader knows, the stack of open elements, and where an element stands in the
//! document.

/// The local names the reader looks for; anything else is `Other`. The stack of open elements
/// holds these, so reading allocates nothing per element.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Tag {
    Project,
    FileHeader,
    Types,
    Pous,
    Pou,
    /// A POU's list of named transitions (docs/INPUTS.md).
    Transitions,
    /// Parts of the FBD/LD elements a wired condition is drawn from (docs/INPUTS.md): an
    /// `inVariable`'s `expression`, a `contact`'s `variable`, a `block`'s `inputVariables`.
    Expression,
    WireVariable,
    InputVariables,
    /// A POU's actions, whose bodies may be SFC charts (`POU.ACTION`, docs/INPUTS.md).
    Actions,
    Action,
    Body,
    Sfc,
    Position,
    ConnectionPointIn,
    Connection,
    Variable,
    AddData,
    Data,
    Iwb,
    /// `ressources` or `resources`.
    Resources,
    /// `ressource` or `resource`.
    Resource,
    Skill,
    Time,
    Condition,
    Inline,
    Reference,
    Step,
    Transition,
    SimultaneousDivergence,
    SimultaneousConvergence,
    SelectionDivergence,
    SelectionConvergence,
    JumpStep,
    MacroStep,
    Other,
}

impl Tag {
    pub(crate) fn of(local: &str) -> Tag {
        match local {
            "project" => Tag::Project,
            "fileHeader" => Tag::FileHeader,
            "types" => Tag::Types,
            "pous" => Tag::Pous,
            "pou" => Tag::Pou,
            "transitions" => Tag::Transitions,
            "expression" => Tag::Expression,
            "variable" => Tag::WireVariable,
            "inputVariables" => Tag::InputVariables,
            "actions" => Tag::Actions,
            "action" => Tag::Action,
            "body" => Tag::Body,
            "SFC" => Tag::Sfc,
            "position" => Tag::Position,
            "connectionPointIn" => Tag::ConnectionPointIn,
            "connection" => Tag::Connection,
            "Variable" => Tag::Variable,
            "addData" => Tag::AddData,
            "data" => Tag::Data,
            "iwb" => Tag::Iwb,
            "ressources" | "resources" => Tag::Resources,
            "ressource" | "resource" => Tag::Resource,
            "skill" => Tag::Skill,
            "time" => Tag::Time,
            "condition" => Tag::Condition,
            "inline" => Tag::Inline,
            "reference" => Tag::Reference,
            "step" => Tag::Step,
            "transition" => Tag::Transition,
            "simultaneousDivergence" => Tag::SimultaneousDivergence,
            "simultaneousConvergence" => Tag::SimultaneousConvergence,
            "selectionDivergence" => Tag::SelectionDivergence,
            "selectionConvergence" => Tag::SelectionConvergence,
            "jumpStep" => Tag::JumpStep,
            "macroStep" => Tag::MacroStep,
            _ => Tag::Other,
        }
    }

    /// Whether text inside this element may be read (into a condition): an inline condition,
    /// an FBD/LD element's `expression` or `variable`, a POU's named transitions. Every element
    /// inside which the reader takes text (`inline_text`, `named_text`) has one of these among
    /// its ancestors or is one; elsewhere text is not read, so the producer leaves out text that
    /// is only white space there (the lines' indentation between tags, a quarter of a plan's
    /// events).
    pub(crate) fn keeps_text(self) -> bool {
        matches!(
            self,
            Tag::Inline | Tag::Expression | Tag::WireVariable | Tag::Transitions
        )
    }
}

/// The open elements: their tags, and their local names one after another in `text` (for
/// messages), each tag with where its name starts.
#[derive(Default)]
pub(super) struct Open {
    pub(super) tags: Vec<(Tag, usize)>,
    text: String,
}

impl Open {
    pub(super) fn push(&mut self, tag: Tag, name: &str) {
        self.tags.push((tag, self.text.len()));
        self.text.push_str(name);
    }

    pub(super) fn pop(&mut self) {
        if let Some((_, at)) = self.tags.pop() {
            self.text.truncate(at);
        }
    }

    pub(super) fn len(&self) -> usize {
        self.tags.len()
    }

    pub(super) fn last_name(&self) -> Option<&str> {
        self.tags.last().map(|&(_, at)| &self.text[at..])
    }

    /// The tags from depth `from` on, at most [`Open::PLACES`] + 1 of them: the reader looks at
    /// places at most that deep below an element, so a longer list (cut, it matches none of
    /// them) need not be copied at every start tag of a deeply nested file.
    pub(super) fn below(&self, from: usize, out: &mut Vec<Tag>) {
        out.clear();
        let below = &self.tags[from.min(self.tags.len())..];
        out.extend(below.iter().take(Self::PLACES + 1).map(|t| t.0));
    }

    /// The deepest place below an SFC element that the reader looks at
    /// (`addData/data/iwb/resources`).
    const PLACES: usize = 4;
}

/// Where an element stands in the document, for the parts read outside SFC elements.
pub(super) enum PathKind {
    FileHeader,
    Pou,
    /// An action of a POU (`pou/actions/action`).
    Action,
    Body,
    Sfc,
    Other,
}

impl PathKind {
    pub(super) fn of(stack: &Open, tag: Tag) -> Self {
        use Tag as T;
        let n = stack.len();
        let open = |i: usize| stack.tags[i].0;
        match tag {
            T::FileHeader if n == 1 && open(0) == T::Project => PathKind::FileHeader,
            // A POU at `n` (docs/INPUTS.md): in `types/pous`, or kept in an `addData/data` anywhere
            // (CODESYS and TwinCAT exports).
            T::Pou if PathKind::pou_at(stack, n) => PathKind::Pou,
            T::Action if PathKind::action_at(stack, n) => PathKind::Action,
            T::Body if n >= 1 && PathKind::owner_at(stack, n - 1) => PathKind::Body,
            T::Sfc if n >= 2 && open(n - 1) == T::Body && PathKind::owner_at(stack, n - 2) => {
                PathKind::Sfc
            }
            _ => PathKind::Other,
        }
    }

    /// Whether an `action` at depth `k` is a POU's (`pou/actions/action`).
    fn action_at(stack: &Open, k: usize) -> bool {
        let t = |i: usize| stack.tags[i].0;
        k >= 2 && t(k - 1) == Tag::Actions && t(k - 2) == Tag::Pou && PathKind::pou_at(stack, k - 2)
    }

    /// Whether the element at depth `k` (open) is a POU or one of its actions: what a `body`
    /// belongs to.
    fn owner_at(stack: &Open, k: usize) -> bool {
        match stack.tags.get(k).map(|t| t.0) {
            Some(Tag::Pou) => PathKind::pou_at(stack, k),
            Some(Tag::Action) => PathKind::action_at(stack, k),
            _ => false,
        }
    }

    /// Whether a `pou` at depth `k` of `stack` (its parents `stack.tags[..k]`) is a POU:
    /// `project/types/pous/pou`, or a `pou` right inside an `addData/data`.
    fn pou_at(stack: &Open, k: usize) -> bool {
        let t = |i: usize| stack.tags[i].0;
        (k == 3 && [t(0), t(1), t(2)] == [Tag::Project, Tag::Types, Tag::Pous])
            || (k >= 2 && t(k - 1) == Tag::Data && t(k - 2) == Tag::AddData)
    }
}
