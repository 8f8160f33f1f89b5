"""Accounts: users with a role (admin, surveyor, viewer) and one API token each.

A token is 32 random bytes (URL-safe text), shown once when the user is made; the store keeps
only its SHA-256 (a lookup key that cannot be turned back into the token: a random token of
256 bits needs no salt or slow hash, unlike a password). Checking a token hashes it, finds
the user by the hash and compares the hashes in constant time.
"""

from __future__ import annotations

import hashlib
import hmac
import re
import secrets

from gsgeo.errors import InputError
from gsgeo.store import NotFoundError, Store
from gsgeo.store.accountrecords import ROLES, UserRecord

#: A user name: a letter or digit first, then letters, digits, '.', '_', '-' (at most 64).
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
#: Names the trail uses for actors that are not users.
RESERVED = ("local", "admin-token")
#: What a token starts with, so that one found in a log or a file can be recognised.
TOKEN_PREFIX = "gsgeo_"


def token_hash(token: str) -> str:
    """The stored form of a token: hex SHA-256 of its UTF-8 text."""
    return hashlib.sha256(token.encode("utf-8", "surrogatepass")).hexdigest()


def check_name(name: str) -> str:
    """``name`` when it is a valid user name, else InputError naming the problem."""
    if not isinstance(name, str) or not NAME.fullmatch(name):
        raise InputError(f"user name {str(name)[:80]!r} is not valid: use 1-64 letters, digits, "
                         "'.', '_' or '-', starting with a letter or digit", field="name")
    if name.lower() in RESERVED:
        raise InputError(f"user name '{name}' is reserved", field="name")
    return name


def check_role(role: str) -> str:
    """``role`` when it is one of ROLES, else InputError naming them."""
    if role not in ROLES:
        raise InputError(f"role {str(role)[:40]!r} is not one of {', '.join(ROLES)}",
                         field="role")
    return role


def add_user(store: Store, name: str, role: str) -> str:
    """Make a user; returns the new token (the only time it is seen). ConflictError when
    the name is taken, InputError on a bad name or role."""
    user = UserRecord(name=check_name(name), role=check_role(role), token_hash="")
    token = TOKEN_PREFIX + secrets.token_urlsafe(32)
    user.token_hash = token_hash(token)
    with store.transaction() as tx:
        tx.insert_user(user)
    return token


def list_users(store: Store) -> list[UserRecord]:
    """Every user, by name (their token hashes included: callers show name, role, date)."""
    with store.transaction(write=False) as tx:
        return tx.list_users()


def remove_user(store: Store, name: str) -> None:
    """Delete a user (their token stops working at once); NotFoundError when there is none."""
    with store.transaction() as tx:
        if not tx.delete_user(name):
            raise NotFoundError(f"user '{name}' does not exist")


def authenticate(store: Store, token: str) -> UserRecord | None:
    """The user holding ``token``, or None."""
    if not token or len(token) > 512:
        return None
    h = token_hash(token)
    with store.transaction(write=False) as tx:
        user = tx.user_by_token_hash(h)
    if user is None or not hmac.compare_digest(user.token_hash, h):
        return None
    return user
