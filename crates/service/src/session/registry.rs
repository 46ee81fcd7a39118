//! The kinds of session this release serves: the one module that names
//! them. Everything else is generic over [`SessionKind`] (the envelope,
//! the store's loop, the event hub) and reaches a kind chosen at run time
//! by its tag through [`KindName::visit`] and the run-time enums here
//! ([`AnyView`], [`EventBody`]).
//!
//! Adding a kind: its module implementing [`SessionKind`], then here a
//! [`KindName`] variant, an arm of [`KindName::visit`], a variant of
//! [`AnyView`] and of [`EventBody`] and its [`Registered`] impl; and its
//! DTOs in the adapters.

use wire_formats::wire::FormatError;

use super::{
    DecodeError, PlotMark, SessionKind, Update, View, correlation::CorrelationSession,
    plot_fusion::PlotFusionSession,
};
use crate::{ServiceError, Violations};

/// The kinds of session this release serves, by name and by tag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KindName {
    Correlation,
    PlotFusion,
}

impl KindName {
    pub const ALL: [KindName; 2] = [KindName::Correlation, KindName::PlotFusion];

    pub fn name(self) -> &'static str {
        match self {
            Self::Correlation => CorrelationSession::NAME,
            Self::PlotFusion => PlotFusionSession::NAME,
        }
    }

    pub fn tag(self) -> u8 {
        match self {
            Self::Correlation => CorrelationSession::TAG,
            Self::PlotFusion => PlotFusionSession::TAG,
        }
    }

    pub fn from_tag(tag: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.tag() == tag)
    }

    /// The kind a create request names (`None`: the default, correlation);
    /// an unknown name is a violation of `field`.
    pub fn parse(name: Option<&str>, field: &str) -> Result<Self, ServiceError> {
        match name {
            None | Some("") => Ok(Self::Correlation),
            Some(n) => Self::ALL
                .into_iter()
                .find(|k| k.name() == n)
                .ok_or_else(|| {
                    let known: Vec<&str> = Self::ALL.iter().map(|k| k.name()).collect();
                    Violations::single(
                        field,
                        format!(
                            "must be one of {}, got '{}'",
                            known.join(", "),
                            crate::validate::quoted(n)
                        ),
                    )
                }),
        }
    }
}

/// Refuses the fields of a create request that belong to another kind than
/// `kind`: `fields` lists (field, present, the kind it belongs to).
pub fn refuse_foreign_fields(
    kind: KindName,
    fields: &[(&str, bool, KindName)],
) -> Result<(), ServiceError> {
    let mut v = Violations::new();
    for (field, present, owner) in fields {
        if *present && *owner != kind {
            v.add(*field, format!("not a field of a {} session", kind.name()));
        }
    }
    v.finish()
}

/// The name of a stored kind tag, for messages.
pub fn tag_name(tag: u8) -> String {
    KindName::from_tag(tag).map_or_else(|| format!("kind {tag}"), |k| k.name().to_string())
}

impl KindName {
    /// Runs `visitor` with this kind's type.
    pub fn visit<V: KindVisitor>(self, visitor: V) -> V::Out {
        match self {
            Self::Correlation => visitor.visit::<CorrelationSession>(),
            Self::PlotFusion => visitor.visit::<PlotFusionSession>(),
        }
    }
}

/// Work done with a kind's type, the kind chosen at run time
/// ([`KindName::visit`]).
pub trait KindVisitor {
    /// What the work gives.
    type Out;
    /// The work, for kind `K`.
    fn visit<K: Registered>(self) -> Self::Out;
}

/// A kind this release serves: how its view and its events become the
/// run-time enums.
pub trait Registered: SessionKind {
    /// The kind's view as any kind's.
    fn any_view(view: View<Self::View>) -> AnyView;
    /// The body of an update event with the plots it marks; an error when
    /// the kind marks none and the event holds some.
    fn event_body(
        update: Update<Self::Update>,
        plots: Vec<PlotMark>,
    ) -> Result<EventBody, FormatError>;
}

/// A session of any kind this release serves, as a client reads it.
#[derive(Debug, Clone, PartialEq)]
pub enum AnyView {
    Correlation(View<<CorrelationSession as SessionKind>::View>),
    PlotFusion(View<<PlotFusionSession as SessionKind>::View>),
}

/// What an event says.
// Always held once, behind the `Arc` every watcher shares.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum EventBody {
    Correlation(Update<<CorrelationSession as SessionKind>::Update>),
    PlotFusion {
        update: Update<<PlotFusionSession as SessionKind>::Update>,
        plots: Vec<PlotMark>,
    },
    /// The session was deleted.
    Deleted,
}

impl Registered for CorrelationSession {
    fn any_view(view: View<Self::View>) -> AnyView {
        AnyView::Correlation(view)
    }

    fn event_body(
        update: Update<Self::Update>,
        plots: Vec<PlotMark>,
    ) -> Result<EventBody, FormatError> {
        // `encode_update` writes the plot marks of every kind: a
        // correlation session has none.
        if !plots.is_empty() {
            return Err(wire_formats::wire::corrupt(
                "plot marks in a correlation event",
            ));
        }
        Ok(EventBody::Correlation(update))
    }
}

impl Registered for PlotFusionSession {
    fn any_view(view: View<Self::View>) -> AnyView {
        AnyView::PlotFusion(view)
    }

    fn event_body(
        update: Update<Self::Update>,
        plots: Vec<PlotMark>,
    ) -> Result<EventBody, FormatError> {
        Ok(EventBody::PlotFusion { update, plots })
    }
}

impl DecodeError {
    /// The error a request gets when it met a session of another kind:
    /// a violation of the kind's batch field (`reports`).
    pub fn for_request<K: SessionKind>(self, id: &str) -> ServiceError {
        match self {
            Self::WrongKind { stored } => ServiceError::InvalidInput(vec![crate::FieldViolation {
                field: K::BATCH_FIELD.into(),
                message: format!(
                    "session '{id}' is a {} session: a {} batch (`{}`) does not apply to it",
                    tag_name(stored),
                    K::NAME,
                    K::BATCH_FIELD
                ),
            }]),
            Self::Other(e) => e,
        }
    }
}
