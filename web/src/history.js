// Undo and redo over the plan's editable state ({procedure, parameters, orientation, at, at_xyz}).

export class History {
  constructor(onChange) {
    this.past = [];
    this.future = [];
    this.onChange = onChange;
  }

  /** Records `before` as the state to go back to. */
  push(before) {
    this.past.push(structuredClone(before));
    this.future = [];
    this.onChange();
  }

  /** The state before `current` (current goes to the redo list), or null. */
  undo(current) {
    if (!this.past.length) return null;
    this.future.push(structuredClone(current));
    const s = this.past.pop();
    this.onChange();
    return s;
  }

  /** The state undone last (current goes back to the undo list), or null. */
  redo(current) {
    if (!this.future.length) return null;
    this.past.push(structuredClone(current));
    const s = this.future.pop();
    this.onChange();
    return s;
  }

  get canUndo() {
    return this.past.length > 0;
  }

  get canRedo() {
    return this.future.length > 0;
  }
}
